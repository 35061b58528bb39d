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
// d for a w x h frame (x y w h; d's roi, else the whole frame).
float      *gain_frame_load(const calib_gain_frame_t *f, int *w, int *h);
const char *gain_frame_name(const calib_gain_frame_t *f, char *buf, size_t size);
void        gain_roi(const calib_gain_data_t *d, int w, int h, int r[4]);

// input.c: the full scale (DN) of a GenICam pixel format.
int gain_format_max(const char *pixel_format);

// linearisation.c: a's linearisation and the Release 4.0 LE of its sweep
// through it (the table's and the parametric form's). false + message.
bool gain_analyse_linearisation(calib_gain_an_t *a);

// spatial.c: roi (x y w h; NULL or w 0: the whole w x h frame) into r.
void gain_region(int w, int h, const int roi[4], int r[4]);

#ifdef __cplusplus
}
#endif
