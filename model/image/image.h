// model/image/image.h — image files: writers (PNG, TIFF), metadata lists,
// the one reader, image lists
//
// Part of model/model.h, whose conventions (units, frames, pixel coordinates,
// errors, model_*_free(NULL)) apply here.
#pragma once

#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>

#include "model/base/base.h"

#ifdef __cplusplus
extern "C" {
#endif

// ---------------------------------------------------------------------------
// Image files (model/image/write.c). Text metadata is a NULL-terminated list of
// key, value, key, value, ..., NULL (may be NULL): PNG tEXt chunks, TIFF
// ImageDescription (as "key: value" lines).

bool model_png16_write(const char *path, int width, int height, const uint16_t *pix,
                       const char *const *meta);

typedef struct {
    int  compression_level;   // zlib 0..9; -1: libpng's default
    bool fast_filter;         // the Sub filter only: ~4x faster on sensor frames, a few % larger
    bool fsync;               // flush the file to the disk before it is renamed into place
    bool quiet;               // errors are kept (model_last_error) but not printed
} model_png_options_t;

// model_png16_write with options (opt NULL: the defaults, as model_png16_write).
// On failure errno holds the cause (ENOSPC for a full disk) and nothing is left
// under path or its temporary name.
bool model_png16_write_opts(const char *path, int width, int height, const uint16_t *pix,
                            const char *const *meta, const model_png_options_t *opt);
// An 8-bit greyscale PNG (previews, masks, pictures for reports), written
// atomically like the 16-bit one; zlib level 1.
bool model_png8_write(const char *path, int width, int height, const uint8_t *pix, const char *const *meta);

// A growing list of metadata (key, value) for the writers above.
typedef struct model_meta model_meta_t;
model_meta_t *model_meta_new(void);
void          model_meta_add(model_meta_t *m, const char *key, const char *fmt, ...)
    __attribute__((format(printf, 3, 4)));
// The NULL-terminated key, value, ... list (valid until the next add or free).
const char *const *model_meta_list(model_meta_t *m);
void          model_meta_free(model_meta_t *m);
// The value of the first entry named key, or NULL.
const char   *model_meta_get(const model_meta_t *m, const char *key);
bool model_tiff_write_float(const char *path, int width, int height, const float *pix,
                            const char *const *meta);
// Multi-page TIFF: page 0 P (float32), page 1 face id (int32, -1 = background),
// pages 2.. the lit mask of each lamp (uint8 0/1), each page named.
bool model_tiff_write_info(const char *path, int width, int height, const float *P,
                           const int32_t *face, const uint8_t *lit, int nlamps,
                           const char *const *lamp_names, const char *const *meta);
// Reading (model/image/read.c): one reader for every command that takes
// images. The format is told by the first bytes, never by the name: PNG
// (grey, grey+alpha, RGB(A), palette; 1 to 16 bits), JPEG (libjpeg-turbo;
// grey or YCbCr/RGB; CMYK refused) and TIFF (first page, strips; grey or
// RGB(A), contiguous or planar; integer 8/16/32 bits or float 32/64).
// Values are kept as stored (an 8-bit image gives 0..255, a 16-bit one
// 0..65535; no scaling). Colour gives one value per pixel by the channel:
// MODEL_CHANNEL_LUMA = Rec. 709 luma weights applied to the stored (encoded)
// values, no transfer curve undone; R, G or B: that channel. A grey image is
// the same whatever the channel. Alpha is ignored.
typedef enum { MODEL_CHANNEL_LUMA, MODEL_CHANNEL_R, MODEL_CHANNEL_G, MODEL_CHANNEL_B } model_channel_t;
#define MODEL_LUMA_R 0.2126
#define MODEL_LUMA_G 0.7152
#define MODEL_LUMA_B 0.0722
typedef enum { MODEL_IMAGE_UNKNOWN, MODEL_IMAGE_PNG, MODEL_IMAGE_JPEG, MODEL_IMAGE_TIFF } model_image_format_t;
// "luma", "r", "g" or "b"; false for anything else.
bool            model_channel_parse(const char *s, model_channel_t *out);
const char     *model_channel_name(model_channel_t ch);
// The channel the path-only readers below use for colour images: luma unless
// a command set another from its --channel option (process-wide, set once
// before the work starts).
void            model_image_set_channel(model_channel_t ch);
model_channel_t model_image_channel(void);
// The format of a file from its first bytes (8 are enough).
model_image_format_t model_image_format(const void *data, size_t len);
// Decode an image file's bytes (name: for messages). meta (may be NULL): a
// PNG's text chunks are added. NULL + model_error naming the file and why
// (not an image, truncated, unsupported layout).
float *model_image_decode(const void *data, size_t len, const char *name, model_channel_t ch, int *width,
                          int *height, model_meta_t *meta);
float *model_image_read(const char *path, model_channel_t ch, int *width, int *height, model_meta_t *meta);
// model_image_read with model_image_channel() and no metadata.
float *model_image_read_float(const char *path, int *width, int *height);
// The W x H image P (row-major) at (x, y) in pixels (pixel centres at whole
// numbers), interpolated bilinearly; outside the image: 0 and *inside false
// (*inside is left as it was otherwise).
double model_image_bilinear(const float *P, int W, int H, double x, double y, bool *inside);
// The same as *pix (free it); false on error.
bool model_tiff_read_float(const char *path, int *width, int *height, float **pix);
// The same as 16-bit values (grey values kept; colour mixed, rounded and
// clamped to 0..65535), optionally with the PNG's text chunks (tEXt, zTXt,
// iTXt) added to meta.
bool model_png_read(const char *path, int *width, int *height, uint16_t **pix);
bool model_png_read_meta(const char *path, int *width, int *height, uint16_t **pix, model_meta_t *meta);
// The files of an --images argument: a directory (its regular files, not the
// hidden ones; not recursive) or a glob pattern (or one file name), sorted by
// name. Whether each is an image is for the reader to say (callers skip what
// it refuses, printing why). false + model_error when there is no file at all.
bool model_image_list(const char *spec, char ***paths, int *n);
void model_image_list_free(char **paths, int n);

#ifdef __cplusplus
}
#endif
