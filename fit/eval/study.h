// fit/eval/study.h — the detection study on the virtual rig (fit/eval/study.c;
// refl verify --study, --study-merge): the truth's T-stiffener, fixed-seed
// cases, the correct description and its corruptions, the correct one on the
// part placed off, four configurations. Writes study.csv (one row per fit:
// config, description, expected, case, score, verdict_correct), timing.csv and
// study.json (units, design, and when every case is in: the summary and ROC).
//
// study.json names its format "refl-study", version 1; the CSV tables carry
// their layout in their header line (study.csv: config, description,
// expected, case, score, verdict_correct, rms_z, median_abs_z; timing.csv:
// config, description, case, seconds, iterations; placement.csv:
// description, case, dx_mm, dy_mm, turn_deg, edge_agreement). A merge reads
// each shard's study.json up to version 1 (a file without "format" and
// "version" is version 1) and refuses a newer one.
#pragma once

#include <jansson.h>
#include <stdbool.h>

#include "fit/verify/verify.h"

#ifdef __cplusplus
extern "C" {
#endif

typedef struct {
    const char         *out;       // output directory (created)
    const char         *truth;     // the virtual rig's truth file (its sample t_stiffener, lamps, materials)
    const char         *calib;     // the chain's calibration directory (camera model, lamps.json, gain, white.json);
                                   // NULL: the lab's (the truth's camera, lamps, kc*I; maps measured noise-free)
    const char *const  *priors;    // the chain's priors files; none: the truth's materials +- 10 %
    int                 npriors;
    int                 cases;     // of the whole study
    const char         *configs;   // comma-separated configurations (priors+maps, priors, no-priors+maps,
                                   // no-priors); NULL: all four
    int                 shard_k, shard_n;   // run the cases c with c mod shard_n = shard_k - 1 (shard_n 0: all)
    double              placement_tol_mm, placement_tol_deg;   // > 0: each case's description registered to its
                                   // images (verify_register) and verified there (placement.csv); 0: as described
    verify_options_t    opt;       // the base options (threads: the cases in parallel)
    json_t             *provenance;   // borrowed: the inputs are added, study.json carries it
} eval_study_opts_t;

typedef struct {
    int  cases, cases_run, ndescriptions, nconfigurations;
    bool complete;   // every case's rows are in (an unsharded run, a merge): study.json has the results
} eval_study_result_t;

// Run the study (or one shard) and write its tables (progress on stderr). false + message.
bool eval_study_run(const eval_study_opts_t *o, eval_study_result_t *r);
// Merge the output directories of the shards of one study (the same design:
// cases, configurations, descriptions, threshold, inputs' hashes; every case
// in exactly one) into out, as the unsharded run writes it: study.csv and the
// results of study.json equal that run's. The shards' provenance (and the
// version of each one's study.json) goes to provenance's "merged_from". false
// + message naming the directory or file:line.
bool eval_study_merge(const char *const *dirs, int ndirs, const char *out, json_t *provenance,
                      eval_study_result_t *r);

#ifdef __cplusplus
}
#endif
