// fit/eval/chain.h — the lab day's chain against a known truth: every calibrated
// and fitted figure of a demo directory (refl demo -o DIR: calib/geometry,
// calib/lamps, calib/gain, calib/white, priors_*.json, verify_*/) next to the
// truth file of the virtual rig it ran on, with the uncertainty refl states
// for it, into DIR/chain.json (refl chain). The one owner of chain.json.
//
// chain.json (format "refl-chain", version 1): {"format", "version",
//   "chain": "...", "truth": path, "dir": path,
//   "units_and_conventions": {...},
//   "entries": [{"name", "group", "value", "truth", "sigma", "unit", "error",
//                "z", "note"}...],
//   "summary": {"entries", "with_sigma", "without_sigma", "z_over_3": [names]},
//   "provenance": {...}}
// value, truth: numbers (or strings for a verdict); sigma: the 1-sigma refl
// states for the value, null where it states none; error = value - truth;
// z = error / sigma (null without sigma). A verdict's error is 0 when it is
// the expected one, 1 when not.
// Errors: NULL / false with the message in model_last_error().
#pragma once

#include <jansson.h>
#include <stdbool.h>

#ifdef __cplusplus
extern "C" {
#endif

// The chain of dir against truth_path (a virtual rig's truth file); the
// provenance prov (borrowed; the inputs read are added to it). NULL + message
// when dir has no calibration to compare (calib/geometry/geometry.json) or
// the truth cannot be read; parts missing from dir are left out with a note
// in "missing".
json_t *eval_chain_compare(const char *dir, const char *truth_path, json_t *prov);

int eval_chain_cmd(int argc, char **argv);

#ifdef __cplusplus
}
#endif
