// calib/gain/internal.h — inside calib/gain/: what its files share that the
// public header (calib/gain/gain.h) does not show.
#pragma once

#include <stdbool.h>
#include <stddef.h>

#include "calib/gain/gain.h"

#ifdef __cplusplus
extern "C" {
#endif

// frames.c: a frame's pixels (w x h; NULL + message naming the manifest line
// or the session step), its name for messages, and the statistics region of
// a w x h frame: roi (x y w h) into r, the whole frame when roi is NULL or
// its w is 0.
float      *gain_frame_load(const calib_gain_frame_t *f, int *w, int *h);
const char *gain_frame_name(const calib_gain_frame_t *f, char *buf, size_t size);
void        gain_region(int w, int h, const int roi[4], int r[4]);

// input.c: f appended to d's frames (d owns its strings then). false +
// message (out of memory; f's strings freed).
bool gain_add_frame(calib_gain_data_t *d, const calib_gain_frame_t *f);

// output.c: a JSON array of n numbers (NaN and infinities: null; v NULL: empty).
json_t *gain_json_numbers(const double *v, int n);

// datasheet.c: gain.json "emva1288" "datasheet" (the standard's rows, each
// with its section) and "refl_rows" (refl's own figures) of a's gain and m.
json_t *gain_datasheet_rows(const calib_gain_opts_t *o, const calib_gain_an_t *a, const calib_gain_maps_t *m);
json_t *gain_refl_rows(const calib_gain_an_t *a, const calib_gain_maps_t *m);

// dark.c: the dark model of a->gain_db (a's dark_* and var_dark_* figures,
// ndark, dark_t_us); *var_fitted: the dark variance's line against exposure
// was fitted (else its mean holds at every exposure). false + message.
bool gain_dark_model(const calib_gain_data_t *d, calib_gain_an_t *a, bool *var_fitted);

// sweep.c: the sweep steps of a->gain_db (light groups of the sweep's role,
// two frames or more; at least min_steps) sorted by exposure, each with its
// dark (the dark pair at its exposure, else the dark model), into a's arrays
// t, mu_y, var_y, mu_d, var_d, mu, var, snr (dev_pct allocated) and a->n.
// false + message.
bool gain_sweep_steps(const calib_gain_data_t *d, int min_steps, bool var_fitted, calib_gain_an_t *a);

// linearisation.c: a's linearisation and the Release 4.0 LE of its sweep
// through it (the table's and the parametric form's). false + message.
bool gain_analyse_linearisation(calib_gain_an_t *a);

#ifdef __cplusplus
}
#endif
