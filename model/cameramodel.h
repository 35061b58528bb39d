// model/cameramodel.h — a .cameramodel file's text checked, then read by libmrcal
//
// libmrcal's parser (mrcal_read_cameramodel_string/_file) reads past the end of
// some damaged texts (a file cut inside a comment, a list or a string) and
// crashes. Every .cameramodel refl reads goes through these functions: the text
// is checked against the grammar mrcal reads (below) first, and mrcal sees only
// a text that passed.
//
// The grammar checked (a subset of a Python dict literal, as mrcal writes it):
// blanks and '#' comments (to the end of the line or of the file) anywhere
// between tokens; one dict '{' KEY ':' VALUE (',' KEY ':' VALUE)* ','? '}'
// and nothing but blanks and comments after it. KEY is a quoted string
// ('...' or "...", optionally prefixed b, no quote, NUL or line break inside,
// closed by the quote that opened it). VALUE is a number, a string or a list
// ('[...]' or '(...)', closed by its own kind) of numbers and lists. Numbers
// are decimal: -?digits[.digits][(e|E)[+-]digits], at most 64 characters,
// finite. The keys mrcal needs, each once: 'lensmodel' (a string naming a lens
// model mrcal knows, before 'intrinsics'), 'intrinsics' (a flat list of exactly
// as many numbers as the lens model has parameters), 'extrinsics' (6 numbers:
// rt_cam_ref), 'imagersize' (2 unsigned integers, 1..65535). No NUL byte.
#pragma once

#include <mrcal/mrcal.h>
#include <stdbool.h>
#include <stddef.h>

#ifdef __cplusplus
extern "C" {
#endif

// true when text[0..len) is a .cameramodel mrcal reads safely; else false and
// model_error(name, LINE, what is wrong) with the line where it was found.
bool model_cameramodel_check(const char *text, size_t len, const char *name);

// The checked text parsed by libmrcal. NULL and model_error naming name (and
// the line) on error. Free with mrcal_free_cameramodel.
mrcal_cameramodel_t *model_cameramodel_parse(const char *text, size_t len, const char *name);

// The file read, checked and parsed (model_cameramodel_parse). NULL and
// model_error naming the file on error.
mrcal_cameramodel_t *model_cameramodel_read(const char *path);

#ifdef __cplusplus
}
#endif
