// fit/eval/internal.h — what the detection study's files share (fit/eval/study.c:
// the design and the run; study_results.c: study.json's results; study_files.c:
// the tables and study.json written and read back; study_merge.c: shards
// merged): its dimensions, its table and the steps one file hands another.
#pragma once

#include <jansson.h>
#include <stdbool.h>
#include <stddef.h>

// study.json's format and the version this refl writes (and reads up to).
#define STUDY_FORMAT "refl-study"
#define STUDY_FORMAT_VERSION 1

#define NANG 4
#define NCONF 4
#define NDESC 14
#define NPLACE 3
#define NCOND (NDESC + NPLACE)

// A condition of the study: a description verified against images of the
// part as placed (place 0) or placed off (place > 0).
typedef struct {
    char label[48];
    char expected[16];   // "correct", "wrong", "placed" (the correct description, the part placed off)
    int  desc;           // the description's index (its scene and views)
    int  place;          // the lab's placement set
} study_cond_t;

// The study's table: one row per (case, configuration, condition).
typedef struct {
    int          cases, nconf, ncond;
    char         conf[NCONF][32];
    study_cond_t cond[NCOND];
    double      *score;     // [case][conf][cond]
    signed char *verdict;   // 1: verdict correct, 0: incorrect, -1: not run here (another shard)
    double      *secs;      // wall time of the fit (timing.csv; not part of the results)
    int         *iters;
    double      *rmsz, *medz;   // the fit's RMS z and median |z| over its used points (the z calibration)
    bool         reg;       // the placement registered (placement.csv)
    float       *pose;      // [case][cond][4]: dx mm, dy mm, turn deg, edge agreement (NAN: not here)
} study_table_t;

static inline size_t study_row(const study_table_t *T, int c, int k, int d)
{
    return ((size_t)c * T->nconf + k) * T->ncond + d;
}

static inline float *study_pose(const study_table_t *T, int c, int d)
{
    return T->pose + ((size_t)c * T->ncond + d) * 4;
}

// The table's arrays for T->cases x T->nconf x T->ncond rows (verdicts -1:
// not run here); false + message (out of memory). study_table_free accepts
// a table never allocated (zeroed).
bool study_table_alloc(study_table_t *T);
void study_table_free(study_table_t *T);
// Every row of the table is in (a verdict for each).
bool study_table_complete(const study_table_t *T);

// study.json's "results": {"summary", "roc", "z_calibration"} from the table
// alone (fit/eval/study_results.c). NULL: out of memory.
json_t *study_results(const study_table_t *T);

// The files (fit/eval/study_files.c): study.csv, timing.csv (and
// placement.csv when the study registers) of the rows in T; study.json with
// the design, the shard (NULL: none), the results when complete, and the
// provenance. false + message.
bool study_write_tables(const char *out, const study_table_t *T);
bool study_write_json(const char *out, const study_table_t *T, json_t *design, json_t *shard,
                      json_t *provenance);
// A study.json read back (path): NULL + message (printed through model_error)
// when it cannot be read or is not a refl-study file of a version this refl
// reads; *version the version read (a file without "format" and "version":
// 1).
json_t *study_read_json(const char *path, int *version);
// DIR/study.csv (timing false) or DIR/timing.csv, and DIR/placement.csv, read
// into T (its shape from the design). false + message naming the file and line.
bool study_read_rows(const char *dir, study_table_t *T, bool timing);
bool study_read_placement(const char *dir, study_table_t *T);
