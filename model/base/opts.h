// model/base/opts.h — the one command-line parser of every refl command.
//
// A command describes its options in a table (model_opt_t[], usually built
// with the MODEL_OPT_* macros below); model_cli_parse fills the destinations,
// checks values (numbers within their range, required options, the count of
// positional arguments) and prints usage errors in one format:
//   refl CMD: <what is wrong>
//   usage: refl CMD SYNOPSIS [options]
//   (refl CMD --help for the options)
// and exits 2 through its return value. --help prints the synopsis, the
// command's description, one line per option from the same table and the exit
// status every refl command shares (model_cli_exit_status). An option's old
// spellings (.old) are still accepted, each noted once a run with the name it
// has now.
//
//   const char *calib = NULL, *out = NULL; double albedo = 0.99; bool verbose = false;
//   model_opt_t opts[] = {
//       MODEL_OPT_STRING("--calib", "DIR", "the calibration directory", &calib, true),
//       MODEL_OPT_DOUBLE("--albedo", "A", "the standard's albedo (default 0.99)", &albedo, 0, 1),
//       MODEL_OPT_FLAG("-v", "--verbose", "print every frame", &verbose),
//   };
//   model_cli_t cli = { .cmd = "calib white", .synopsis = "SESSION", .opts = opts,
//                       .nopts = MODEL_NOPTS(opts), .min_positional = 1, .max_positional = 1 };
//   int rc = model_cli_parse(&cli, argc, argv);
//   if (rc != MODEL_CLI_OK) return rc == MODEL_CLI_HELP ? 0 : rc;
//   ... cli.positional[0] ...
#pragma once

#include <stdbool.h>
#include <stdio.h>

#ifdef __cplusplus
extern "C" {
#endif

typedef enum {
    MODEL_OPT_KIND_FLAG,     // bool *: set true when given
    MODEL_OPT_KIND_STRING,   // const char **: the value as given (dest may be NULL: read it with
                             // model_cli_value, or convert it with model_cli_double / _long)
    MODEL_OPT_KIND_INT,      // int *: a whole number within [min, max]
    MODEL_OPT_KIND_DOUBLE,   // double *: a finite number within [min, max]
    MODEL_OPT_KIND_LIST,     // model_opt_list_t *: every value of a repeated option (--session A --session B)
                             // and, when min is 1, the arguments after it up to the next option
                             // (--images A B C)
} model_opt_kind_t;

// The values of a list option: v[0..n-1] point into argv; v has cap slots
// (the caller's array; more values are a usage error).
typedef struct {
    const char **v;
    int          n, cap;
} model_opt_list_t;

typedef struct {
    const char      *name;      // "--calib" or "-o"
    const char      *alias;     // a second spelling ("--verbose" for "-v"), or NULL
    const char      *metavar;   // "DIR"; NULL for flags
    const char      *help;      // one line (may be longer: it is printed as it is)
    model_opt_kind_t kind;
    void            *dest;      // where the value goes (see the kinds)
    double           min, max;  // numbers: the accepted range, inclusive
    bool             required;
    bool             given;     // out: the option was on the command line
    const char      *value;     // out: its value as given ("" for a flag)
    const char      *old;       // its old spellings, space-separated ("--camera"), or NULL: each is accepted
                                // and noted once a run (model_note): "--camera FILE: the option is
                                // --camera-model (the old spelling still works)"; never shown by --help
    unsigned         noted;     // out: the old spellings noted so far (a bit each)
} model_opt_t;

// Each macro takes, after its own arguments, optional designated fields of
// model_opt_t: MODEL_OPT_STRING("--camera-model", "FILE", "...", &cam, true, .old = "--camera").
#define MODEL_OPT_FLAG(name_, alias_, help_, dest_, ...) \
    { .name = name_, .alias = alias_, .help = help_, .kind = MODEL_OPT_KIND_FLAG, .dest = dest_, ##__VA_ARGS__ }
#define MODEL_OPT_STRING(name_, metavar_, help_, dest_, required_, ...)                                        \
    { .name = name_, .metavar = metavar_, .help = help_, .kind = MODEL_OPT_KIND_STRING, .dest = dest_,        \
      .required = required_, ##__VA_ARGS__ }
#define MODEL_OPT_INT(name_, metavar_, help_, dest_, min_, max_, ...)                                          \
    { .name = name_, .metavar = metavar_, .help = help_, .kind = MODEL_OPT_KIND_INT, .dest = dest_,           \
      .min = min_, .max = max_, ##__VA_ARGS__ }
#define MODEL_OPT_DOUBLE(name_, metavar_, help_, dest_, min_, max_, ...)                                       \
    { .name = name_, .metavar = metavar_, .help = help_, .kind = MODEL_OPT_KIND_DOUBLE, .dest = dest_,        \
      .min = min_, .max = max_, ##__VA_ARGS__ }
// A string option (metavar given) or a flag (metavar NULL) read after parsing
// with model_cli_value / model_cli_double / model_cli_long.
#define MODEL_OPT_VALUE(name_, metavar_, help_, required_, ...)                                                \
    { .name = name_, .metavar = metavar_, .help = help_,                                                      \
      .kind = (metavar_) ? MODEL_OPT_KIND_STRING : MODEL_OPT_KIND_FLAG, .required = required_, ##__VA_ARGS__ }
// A list option (see MODEL_OPT_KIND_LIST); greedy: it also takes the arguments
// after it up to the next option.
#define MODEL_OPT_LIST(name_, metavar_, help_, dest_, greedy_, required_, ...)                                 \
    { .name = name_, .metavar = metavar_, .help = help_, .kind = MODEL_OPT_KIND_LIST, .dest = dest_,          \
      .min = (greedy_) ? 1 : 0, .required = required_, ##__VA_ARGS__ }
// The output of every command: -o, --out PATH (dest may be NULL: model_cli_value(c, "-o")).
#define MODEL_OPT_OUT(metavar_, help_, dest_, required_, ...)                                                  \
    { .name = "-o", .alias = "--out", .metavar = metavar_, .help = help_, .kind = MODEL_OPT_KIND_STRING,      \
      .dest = dest_, .required = required_, ##__VA_ARGS__ }
#define MODEL_NOPTS(table) ((int)(sizeof(table) / sizeof((table)[0])))

enum { MODEL_CLI_POSITIONAL_MAX = 1024 };

typedef struct {
    const char  *cmd;             // "calib white" (printed as "refl calib white")
    const char  *synopsis;        // the positional part of the usage line, e.g. "SESSION"
    const char  *about;           // --help: the paragraph(s) after the usage line; may be NULL
    const char  *epilog;          // --help: text after the option list; may be NULL
    model_opt_t *opts;
    int          nopts;
    int          min_positional, max_positional;
    bool         numbers_positional; // "-30" is a positional number (an angle), not an option
    bool         repeat_ok;          // an option given twice takes the last value (else an error)
    // out
    const char  *positional[MODEL_CLI_POSITIONAL_MAX];
    int          npositional;
} model_cli_t;

enum { MODEL_CLI_OK = -1, MODEL_CLI_HELP = 0, MODEL_CLI_USAGE = 2 };

// Parse argv[1..argc-1] (argv[0] is the command's name). Returns MODEL_CLI_OK,
// MODEL_CLI_HELP after printing the help on stdout, or MODEL_CLI_USAGE (2, the
// exit status of a usage error) after printing the error on stderr.
int  model_cli_parse(model_cli_t *c, int argc, char **argv);
// The help text (usage line, about, options, epilog, exit status, version).
void model_cli_help(const model_cli_t *c, FILE *f);
// The exit status of every refl command (0 done, 1 error, 2 usage, 3 paused,
// 4 an incorrect verdict under refl verify --fail-on-incorrect), as --help prints it.
void model_cli_exit_status(FILE *f);
enum { MODEL_EXIT_OK = 0, MODEL_EXIT_ERROR = 1, MODEL_EXIT_USAGE = 2, MODEL_EXIT_PAUSED = 3,
       MODEL_EXIT_INCORRECT = 4 };
// The short usage line and the --help hint (after an error of the command's own).
void model_cli_usage(const model_cli_t *c, FILE *f);
// A usage error found after parsing (two options that exclude each other, ...):
// "refl CMD: <message>", the usage line; returns MODEL_CLI_USAGE.
int  model_cli_error(const model_cli_t *c, const char *fmt, ...) __attribute__((format(printf, 2, 3)));
// The option of the table with this name (or alias); NULL when there is none.
model_opt_t *model_cli_opt(model_cli_t *c, const char *name);
// The value of option name as given, NULL when it was not given.
const char  *model_cli_value(model_cli_t *c, const char *name);
// A string option converted after parsing: absent keeps *out; a bad value is a
// usage error ("option NAME: 'V' is not a number" / "... is out of range
// (RANGE_TEXT)"); returns 0 or MODEL_CLI_USAGE. lo is exclusive when lo_open.
int model_cli_double(model_cli_t *c, const char *name, double *out, double lo, bool lo_open, double hi,
                     const char *range_text);
int model_cli_long(model_cli_t *c, const char *name, long *out, long lo, long hi);

// --channel of the commands that read images (model/image/read.c): how a
// colour image becomes one value per pixel. Put MODEL_OPT_CHANNEL in the
// table and call model_cli_channel after parsing (it sets the process-wide
// model_image_set_channel; absent: luma); 0 or MODEL_CLI_USAGE.
#define MODEL_OPT_CHANNEL                                                                                       \
    MODEL_OPT_VALUE("--channel", "luma|r|g|b", "colour images: Rec. 709 luma (0.2126 R + 0.7152 G + 0.0722 B "   \
                    "of the stored values; default) or one channel", false)
int model_cli_channel(model_cli_t *c);

// --units of the commands that read a scene (model/scene/scene.c): the unit of the
// scene file's coordinates. MODEL_OPT_UNITS in the table; model_cli_units
// after parsing sets *unit_mm (mm per unit) when given (absent: unchanged,
// 0 = mm not said, which lets a tiny mesh warn); 0 or MODEL_CLI_USAGE.
#define MODEL_OPT_UNITS                                                                                         \
    MODEL_OPT_VALUE("--units", "mm|m|in", "unit of the scene file's coordinates (default mm; a mesh smaller "   \
                    "than 5 mm read without --units gets a warning)", false)
int model_cli_units(model_cli_t *c, double *unit_mm);

#ifdef __cplusplus
}
#endif
