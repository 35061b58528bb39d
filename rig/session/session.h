// rig/session/session.h — capture sessions: plans, the journal, the session reader
// (rig_session_*) and the capture itself.
#pragma once

#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>

#include <jansson.h>

#include "model/model.h"
#include "rig/devices.h"

#ifdef __cplusplus
extern "C" {
#endif

typedef struct rig rig_t;   // rig/rig.h
typedef struct rig_operator rig_operator_t;   // the operator's answers (below)

// ---------------------------------------------------------------------------
// Capture sessions (rig/session/plan.c, rig/session/journal.c, rig/session/capture.c, rig/cmd_capture.c)
//
// A plan file (INI, see examples/plans/) says what to capture:
//   [plan]     name = TEXT; operator = TEXT; notes = TEXT (all optional); format_version =
//              the plan format's version (RIG_PLAN_FORMAT_VERSION, which rig_plan_text
//              writes; absent: 1; a higher one than this refl reads is refused)
//   [sample]   name = NAME (on a virtual rig: a [sample NAME] of its truth file, put on the
//              table); kind = material_coupon | reference_white | chessboard | mirror_sphere |
//              workpiece | uniform_source; tilt_deg = the wedge the sample stands on (-80..80,
//              default 0), tilt_azimuth_deg = the azimuth of the wedge's hinge axis (default
//              0): the operator puts the sample so (an operator step, below); instruction =
//              TEXT (optional) replaces the operator step's generated instruction
//   [operator] end = TEXT (optional): one more operator step after the last frame (e.g.
//              "take the coupon off the wedge")
//   [angles]   list = DEG DEG ... | range = START STOP STEP (STOP included when reached)
//   [lamps]    sets = SET; SET; ...   a SET is NAME+NAME..., "all" or "none"
//   [exposure] mode = fixed: list_us = US US ...
//              mode = auto: list_us = the bracket ladder (captured longest first; the
//              bracket ends with the first frame whose brightest pixel of interest is at
//              or below target_fraction (0 < f <= 1, default 0.9) of full scale; the other
//              exposures of the ladder are journalled as skipped); roi = X Y W H (the pixels
//              of interest, default the whole frame)
//              gain = G (camera unit, default 0); pixel_format = Mono8|Mono12|Mono16 (default Mono12;
//              also Mono10 and the packed formats of rig/camera/pixfmt.h)
//   [capture]  repeats = N (frames per exposure, default 1); dark_every = N (a dark frame,
//              lamps off at the step's exposure, after every N light steps; 0 = none);
//              settle_ms = after each motion (default 0); lamp_settle_ms = extra after each
//              lamp change beyond the lamps' own (default 0); frame_timeout_s = how long to
//              wait for a frame beyond its exposure (default 10); retries = captures tried
//              again after a camera time-out before the session pauses (default 2)
//   [view NAME] (optional, any number; rig/session/plan_views.c) what one turntable angle takes:
//              angle_deg = one of [angles] (at most one view per angle); sets = SET; SET ...
//              (some of [lamps] sets, written the same way; default all of them); list_us =
//              US US ... (some of [exposure] list_us; default all). An angle without a view
//              takes every lamp set and exposure. `refl plan lamps` writes a view per angle
//              (each view's own lamps and exposure).
// Order: the operator step of [sample] first, then angle, then lamp set, then
// repeat, then exposure (a bracket stays together), then [operator] end. Every
// problem is reported through model_error naming the plan file and line.
//
// Operator steps (RIG_STEP_OPERATOR): the session stops, switches the lamps
// off, prints the instruction ("put coupon glossy_plastic (material_coupon) on
// the 40 deg wedge ...", generated from [sample] kind, name, tilt_deg and
// tilt_azimuth_deg) and waits for the operator's answer (rig_operator_t:
// Enter on a terminal, --yes, --operator-input FILE; 'q' pauses: exit 3).
// The answer is journalled (the step done and an events row 'operator' saying
// how and when); an answered step is never asked again, an unanswered one is
// asked on --resume. Nothing moves before the leading operator steps are
// answered: the stage homes after them. The virtual rig plays the operator: an answered step's
// pose (the [sample] on its wedge) is applied to it (rig_virtual_set_sample_pose)
// and applied again on --resume; a real rig only waits.
//
// A session directory: session.sqlite (tables schema_version, session, steps,
// frames, events; every step is written pending at the start) and
// frames/sNNNNNN.png (step index; 16-bit grey PNG with metadata), or with
// several cameras frames/sNNNNNN_NAME.png, one per camera (NAME: the rig
// file's camera name): each step triggers every camera, one after the other
// in the rig file's order, at the step's angle and lamps; a step is done when
// every camera's frame is committed, and --resume takes the missing
// (step, camera) frames only. The journal's schema versions (table
// schema_version; rig/session/journal.c): 1, frames keyed by step (one
// camera); 2, frames keyed by (step, camera), written by this refl. Versions 1
// and 2 are read (a version-1 journal's frames as camera "camera"; --resume
// migrates it to 2 first); a higher version is refused. A frame is
// written to frames/.sNNNNNN.png.part, fsync'ed, hashed, committed with its row
// (one transaction), then linked to its name (link(2): nothing is overwritten)
// and the temporary name removed; --resume re-links committed frames whose link
// a crash prevented and deletes uncommitted temporary files.

typedef enum { RIG_STEP_LIGHT, RIG_STEP_DARK, RIG_STEP_OPERATOR } rig_step_kind_t;

typedef struct {
    int             index;          // 0-based position in the session
    rig_step_kind_t kind;
    int             angle_index, lamp_set, exposure_index, repeat;
    int             group;          // auto bracketing: steps of one (angle, lamp set, repeat) bracket
    double          angle_deg;
    uint32_t        lamp_mask;      // bits of the rig's lamps (rig_plan_bind)
    char            lamps[256];     // "east+west", "none"
    double          exposure_us, gain;
    int             op;             // RIG_STEP_OPERATOR: its rig_plan_t ops[] entry (else -1)
} rig_step_t;

// An operator step's content: the instruction and, for the [sample] step, the
// pose the operator sets up (a virtual rig applies it when the step is answered).
typedef struct {
    char   instruction[512];
    bool   pose;                    // sample, tilt_deg, tilt_azimuth_deg apply
    char   sample[64];
    double tilt_deg, tilt_azimuth_deg;
} rig_op_step_t;

// A [view NAME] section: the lamp sets and exposures one angle takes.
typedef struct {
    char     name[64];
    int      line;                  // the section header's line
    int      angle_index;           // into angles_deg
    bool    *sets;                  // nlamp_sets: taken at the angle
    bool    *exposures;             // nexposures (auto: the sorted ladder's order)
} rig_plan_view_t;

#define RIG_PLAN_FORMAT_VERSION 1   // the plan format written and read (versions 1 to this)

typedef struct {
    char    *path, *text;           // file name, contents
    int      format_version;        // [plan] format_version as read (1 when absent)
    char     sha256[65];
    char     name[128], operator_name[128], notes[512];
    char     sample[64], sample_kind[32];
    double   tilt_deg, tilt_azimuth_deg;   // the sample's wedge (see rig_virtual_set_sample_pose)
    int      nangles;
    double  *angles_deg;
    int      nlamp_sets;
    char   (*lamp_sets)[256];       // as written, normalised ("east+west", "none", "all")
    int      lamp_sets_line;
    bool     auto_exposure;
    int      nexposures;
    double  *exposures_us;          // auto: sorted longest first
    int      exposure_line;
    double   target_fraction;
    int      roi[4];                // x y w h; w = 0: whole frame
    double   gain;
    char     pixel_format[16];
    int      repeats, dark_every;
    double   settle_ms, lamp_settle_ms;
    double   frame_timeout_s;
    int      retries;
    int      nsteps;
    rig_step_t *steps;              // built by rig_plan_load (lamp_mask 0 until rig_plan_bind)
    int      nops;
    rig_op_step_t *ops;             // the operator steps' content (rig_step_t op)
    int      nviews;                // [view NAME] sections, in file order
    rig_plan_view_t *views;
} rig_plan_t;

// Parse a plan file (or text, for tests: name is used in messages) and build
// its step list. NULL on error (model_last_error names file and line).
rig_plan_t *rig_plan_load(const char *path);
rig_plan_t *rig_plan_parse(const char *text, size_t len, const char *name);
void        rig_plan_free(rig_plan_t *p);
// Check the plan against an open rig before anything moves: lamp names exist,
// angles within the turntable's range (+-10000 deg; a turntable is needed when
// any angle is not 0), a camera exists and accepts every exposure, the gain and
// the pixel format (set and read back, then restored), the ROI fits the frame,
// the sample exists on a virtual rig (it is not posed: the operator step does
// that, rig_plan_operator_pose). Fills every step's lamp_mask. 0 or a
// RIG_ERR_* (message names the plan file and line).
int rig_plan_bind(rig_plan_t *p, rig_t *r);
// The operator's action of operator step `step` on rig r: on a virtual rig its
// pose is applied (rig_virtual_set_sample_pose); on a real rig nothing (the
// operator did it). *what (may be NULL) says which. 0 or a RIG_ERR_*.
int rig_plan_operator_pose(const rig_plan_t *p, rig_t *r, int step, char *what, size_t size);

// The hardware floor of a step list on a rig: the sum of motions (trapezoidal
// profile from the rig's speed/acceleration), settles (max of motion settle and
// lamp settle when both happen at a step) and exposures; seconds.
double rig_plan_floor_s(const rig_plan_t *p, const rig_t *r, int from_step);

// The plan as a plan file's text (rig/session/plan.c, at its end): every section with
// every value ([plan] format_version = RIG_PLAN_FORMAT_VERSION first, angles as a
// list, [view NAME] sections as held), that
// rig_plan_parse reads back to the same steps. comment (may be NULL): lines
// written first as '# ' comments. NULL (model_error) when a text field holds
// what a plan file cannot (a line break, '#' after a blank, ';' in a lamp set).
// Caller frees with free().
char *rig_plan_text(const rig_plan_t *p, const char *comment);

// The journal: DIR/session.sqlite (WAL, one transaction per frame).
// rig_journal_create and rig_journal_resume are the writer's (refl capture):
// read-write, WAL; resume migrates a version-1 journal to version 2, and
// refuses a directory it cannot write. rig_journal_open is every reader's: it
// never writes (no WAL switch, no migration) and reads a session in a
// directory it cannot write (another user's, a read-only archive), with the
// commits of a WAL left beside the journal (rig/session/journal.c says how).
typedef struct rig_journal rig_journal_t;

// The frame table: one list for the rig_frame_row_t fields, the journal's
// frames table (CREATE / INSERT / SELECT) and `refl session export` (CSV and
// JSON, in this order):
//   _(KIND, field, "column", "column declaration", "CSV format", text size)
// KIND: INT (int), REAL (double), TEXT (char field[size]), U64 (uint64_t),
// UTC (a column only: the UTC text of the REAL field `field`, for people
// reading the database; not in the struct, not exported). `file` is relative
// to the session directory. The camera's radiometric state (rig_frame_meta_t):
// gain_unit (the unit of `gain`, GenICam's <Unit>: "dB", "x", or "raw" when
// the camera states none; model_gain_factor converts; empty where the journal
// lacks the column, whose gains are dB), black_level and temperature_c (NULL
// in the database where the camera has none; read back as 0), gamma (1 when
// off), firmware, camera_settings (the automatics, gamma, LUT and transport
// settings refl found, switched off and read back). A version-1 journal may
// lack gain_unit .. camera_settings: they read as NULL, and the first frame
// written (a resume) adds them.
// A frame's key is (step, camera): `camera` (last,
// so that readers of the CSV by position keep their columns) is the
// rig file's name of the camera that took it ("camera" for a plain [camera]
// and a one-camera virtual rig); rows come in step order, then camera order.
#define RIG_FRAME_COLUMNS(_)                                                                    \
    _(INT,  step,               "step",               "INTEGER NOT NULL REFERENCES steps(idx)", "%d", 0) \
    _(TEXT, file,               "file",               "TEXT UNIQUE NOT NULL", "%s",   64)  \
    _(TEXT, sha256,             "sha256",             "TEXT NOT NULL",        "%s",   65) \
    _(UTC,  t_trigger_utc_s,    "t_trigger_utc",      "TEXT",                 "",     0)  \
    _(UTC,  t_written_utc_s,    "t_written_utc",      "TEXT",                 "",     0)  \
    _(REAL, t_trigger_utc_s,    "t_trigger_s",        "REAL",                 "%.6f", 0)  \
    _(REAL, t_written_utc_s,    "t_written_s",        "REAL",                 "%.6f", 0)  \
    _(REAL, commanded_deg,      "commanded_deg",      "REAL",                 "%.10g", 0) \
    _(REAL, measured_deg,       "measured_deg",       "REAL",                 "%.6f", 0)  \
    _(TEXT, lamps,              "lamps",              "TEXT",                 "%s",   256) \
    _(REAL, exposure_us,        "exposure_us",        "REAL",                 "%.10g", 0) \
    _(REAL, gain,               "gain",               "REAL",                 "%.10g", 0) \
    _(REAL, mean,               "mean",               "REAL",                 "%.4f", 0)  \
    _(REAL, max,                "max",                "REAL",                 "%.0f", 0)  \
    _(REAL, roi_max,            "roi_max",            "REAL",                 "%.0f", 0)  \
    _(REAL, saturated_fraction, "saturated_fraction", "REAL",                 "%.8g", 0)  \
    _(INT,  width,              "width",              "INTEGER",              "%d",   0)  \
    _(INT,  height,             "height",             "INTEGER",              "%d",   0)  \
    _(TEXT, pixel_format,       "pixel_format",       "TEXT",                 "%s",   16) \
    _(U64,  frame_id,           "frame_id",           "INTEGER",              "%llu", 0)  \
    _(TEXT, gain_unit,          "gain_unit",          "TEXT",                 "%s",   16) \
    _(REAL, black_level,        "black_level",        "REAL",                 "%.10g", 0) \
    _(REAL, gamma,              "gamma",              "REAL",                 "%.6g", 0)  \
    _(REAL, temperature_c,      "temperature_c",      "REAL",                 "%.2f", 0)  \
    _(TEXT, firmware,           "firmware",           "TEXT",                 "%s",   64) \
    _(TEXT, camera_settings,    "camera_settings",    "TEXT",                 "%s",   512) \
    _(TEXT, camera,             "camera",             "TEXT NOT NULL DEFAULT 'camera'", "%s", 32)

#define RIG_FRAME_FIELD_INT(name, size)  int name;
#define RIG_FRAME_FIELD_REAL(name, size) double name;
#define RIG_FRAME_FIELD_TEXT(name, size) char name[size];
#define RIG_FRAME_FIELD_U64(name, size)  uint64_t name;
#define RIG_FRAME_FIELD_UTC(name, size)
#define RIG_FRAME_FIELD_(kind, name, column, decl, csv, size) RIG_FRAME_FIELD_##kind(name, size)

typedef struct {
    RIG_FRAME_COLUMNS(RIG_FRAME_FIELD_)
} rig_frame_row_t;

// `refl session export`: the rows as CSV (a header line with the field names,
// then one line per row) or as a JSON document (NULL: out of memory):
//   {"format": "refl-session-frames", "version": 1, "frames": [{FIELD: VALUE, ...}, ...]}
// (a REAL that is not finite is null).
#define RIG_SESSION_FRAMES_FORMAT  "refl-session-frames"
#define RIG_SESSION_FRAMES_VERSION 1
void    rig_frame_rows_write_csv(FILE *f, const rig_frame_row_t *rows, int n);
json_t *rig_frame_rows_json(const rig_frame_row_t *rows, int n);

// Create DIR/session.sqlite (fails when it exists) with the session and every
// step pending. session_json: a JSON object of session facts (camera serials,
// settings snapshot, calibrations, versions, operator notes), format
// RIG_SESSION_FACTS_FORMAT version RIG_SESSION_FACTS_VERSION (model_json_set_format;
// facts without the keys read as version 1; readers refuse a higher version).
#define RIG_SESSION_FACTS_FORMAT  "refl-session-facts"
#define RIG_SESSION_FACTS_VERSION 1
int  rig_journal_create(rig_journal_t **out, const char *dir, const rig_plan_t *p, const char *rig_path,
                        const char *rig_text, const char *rig_sha256, const char *session_json);
int  rig_journal_open(rig_journal_t **out, const char *dir);
int  rig_journal_resume(rig_journal_t **out, const char *dir);
void rig_journal_close(rig_journal_t *j);
// Stored plan/rig: path, text, sha256 (caller frees with free()).
int  rig_journal_source(rig_journal_t *j, const char *which, char **path, char **text, char **sha256);
int  rig_journal_nsteps(rig_journal_t *j);
// The session facts (JSON object text, as given at create). Caller frees.
int  rig_journal_facts(rig_journal_t *j, char **json);
// The session facts parsed (rig/session/reader.c): *facts NULL when there are
// none or they are not JSON. false (model_error_set naming the journal) when
// they cannot be read or are of a version above RIG_SESSION_FACTS_VERSION.
bool rig_journal_facts_read(rig_journal_t *j, json_t **facts);
// SQLite's PRAGMA integrity_check on the journal: *result (caller frees with
// g_free) is "ok" when the database is intact, else SQLite's findings (joined
// by "; "). 0, or a RIG_ERR_* when the check cannot run.
int  rig_journal_integrity(rig_journal_t *j, char **result);
// The same as an error: 0 when intact, else RIG_ERR_IO (model_last_error names
// the journal and SQLite's findings).
int  rig_journal_check(rig_journal_t *j);
// DIR/session.sqlite, as opened.
const char *rig_journal_path(const rig_journal_t *j);
// Steps (as stored) and their status: 'p'ending, 'd'one, 's'kipped. Caller frees both.
// Operator steps come back with kind RIG_STEP_OPERATOR and op -1.
int  rig_journal_steps(rig_journal_t *j, rig_step_t **steps, char **status, int *n);
// A step's note (an operator step: its instruction; a skipped step: why), or
// NULL. Caller frees.
char *rig_journal_step_note(rig_journal_t *j, int step);
// An operator step answered: its status done and an events row 'operator'
// (message how), one transaction.
int  rig_journal_operator_done(rig_journal_t *j, int step, const char *how);
int  rig_journal_frames(rig_journal_t *j, rig_frame_row_t **rows, int *n);
// One transaction: the frame row and, when step_done (its step's last
// camera), its step done.
int  rig_journal_frame_done(rig_journal_t *j, const rig_frame_row_t *f, bool step_done);
int  rig_journal_step_skipped(rig_journal_t *j, int step, const char *why);
// Event log: kind = start, resume, retry, fault, pause, stop, complete, info, operator.
int  rig_journal_event(rig_journal_t *j, int step, const char *kind, const char *fmt, ...)
    __attribute__((format(printf, 4, 5)));
int  rig_journal_set_state(rig_journal_t *j, const char *state);   // running paused stopped fault complete
int  rig_journal_state(rig_journal_t *j, char *out, size_t size);

// Reading a finished (or paused) session for the analyses (rig/session/reader.c).
// A session's frames (in step order) and its facts, for the analyses.
typedef struct {
    char            *dir;
    rig_frame_row_t *rows;
    int              n;
    char             plan_sha256[65], rig_sha256[65];
    char            *plan_text;        // the stored plan
    json_t          *facts;            // session facts (camera, virtual rig, ...); may be NULL
} rig_session_t;

// NULL on error (model_last_error names the directory; a journal that fails
// SQLite's integrity check is an error). rig_session_open: every frame; rig_session_open_camera: the frames of one camera (NULL: the
// session's first camera; an analysis of one camera reads a session of
// several so), an error naming the cameras when it has none of that name.
rig_session_t *rig_session_open(const char *dir);
rig_session_t *rig_session_open_camera(const char *dir, const char *camera);
// The cameras of a session's frames in first-seen order (at most max names
// into names, pointers into s->rows): their number.
int            rig_session_cameras(const rig_session_t *s, const char **names, int max);
void             rig_session_free(rig_session_t *s);
// Frame i as float DN (its pixel format's values); checks the file's sha256
// against the journal first. NULL on error (names the file). Caller frees.
float           *rig_session_frame(const rig_session_t *s, int i, int *width, int *height);


// What a run did (rig_capture_run fills it when asked): the command prints it.
typedef struct {
    bool   complete;            // the session is complete (exit 0)
    bool   was_complete;        // --resume found it complete: nothing was done
    int    steps;               // the plan's steps
    int    frames, frames_run;  // the session's frames, those written by this run
    bool   auto_exposure;       // auto bracketing (the steps it skips take no frame)
    double wall_s;              // this run, without the operator's time and homing
    double floor_s;             // the hardware floor of the steps this run carried out
    double camera_s;            // in the camera: trigger to frame in hand, summed
    double writer_wait_s;       // waiting for the writer's queue, summed
} rig_capture_summary_t;

// Run (or continue) a session. Exit codes of refl capture: 0 complete, 1 error
// or fault (stopped; model_last_error says why), 3 paused (SIGINT, an operator
// step not answered or the camera not answering: a note says why; resume
// later). Progress, homing, resume and pause go through model_note /
// model_progress (the command's prefix); nothing is printed on stdout.
typedef struct {
    const char *plan_path, *rig_path, *dir;
    bool        resume, allow_changed;
    const char *operator_name, *notes;
    const char *command_line;
    // A calibration directory (refl calib ... -o DIR, or one holding geometry/,
    // lamps/, gain/, white/): its files are recorded in the session facts by
    // path and sha256 (NULL: none). Frames stay raw.
    const char *calib_dir;
    int         progress;           // -1 auto (bar on a TTY), 0 a note a step, 1 bar (model_progress)
    // Called before each step is carried out (after the rig is open): for
    // tests (fault injection) and instrumentation; may be NULL.
    void      (*before_step)(void *ctx, rig_t *r, int step);
    void       *hook_ctx;
    // Out (may be NULL): what the run did.
    rig_capture_summary_t *summary;
    // Who answers the operator steps (NULL: the terminal, or a pause when
    // stdin is not one). Shared by the sessions of one command.
    rig_operator_t *op;
} rig_capture_opts_t;
int rig_capture_run(const rig_capture_opts_t *o);

// ---------------------------------------------------------------------------
// The operator's answers (rig/session/operator.c)
//
// yes: every operator step is answered done (scripts, CI, the demo).
// input: one answer per line, consumed in order across every session of the
// command: empty, done, y, yes = done; q, pause, stop = pause; end of file =
// pause; anything else is an error naming FILE:LINE. Neither: on a terminal
// (stdin) the instruction is shown and Enter answers done, q pauses; when stdin
// is not a terminal the session pauses (exit 3) with a hint.
// NULL on error (both given, FILE unreadable; model_last_error says).
rig_operator_t *rig_operator_open(bool yes, const char *input);
void            rig_operator_close(rig_operator_t *op);
enum { RIG_OPERATOR_DONE = 0, RIG_OPERATOR_PAUSE = 1 };
// Ask for step `step`'s instruction: RIG_OPERATOR_DONE (how: "terminal",
// "--yes", "--operator-input FILE:LINE", with the UTC time), RIG_OPERATOR_PAUSE
// (how: why), or a negative RIG_ERR_* (a bad answer line: the message names
// FILE:LINE).
int  rig_operator_ask(rig_operator_t *op, int step, const char *instruction, char *how, size_t size);
// Whether a session of this reader paused (exit 3) since it was opened: the
// calibrations exit 3 then.
bool rig_operator_paused(const rig_operator_t *op);
void rig_operator_set_paused(rig_operator_t *op);
// The options of every command that captures (model/base/opts.h tables).
#define RIG_OPERATOR_OPTS(yes_dest, input_dest)                                                                \
    MODEL_OPT_FLAG("--yes", NULL, "answer every operator step as done (scripts, CI; see README, Operator "     \
                   "steps)", yes_dest),                                                                       \
    MODEL_OPT_STRING("--operator-input", "FILE", "the operator's answers, one a line (empty|done|y|yes: done; " \
                     "q|pause|stop: pause)", input_dest, false)

// `refl capture`, `refl session` (rig/cmd_capture.c).
int rig_cmd_capture(int argc, char **argv);
int rig_cmd_session(int argc, char **argv);

#ifdef __cplusplus
}
#endif
