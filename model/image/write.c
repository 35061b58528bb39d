// model/image/write.c — image files written: 16-bit greyscale PNG (libpng) with tEXt
// metadata, float32 and multi-page TIFF (libtiff) with ImageDescription. The
// readers (PNG, JPEG, TIFF) are in model/image/read.c.
//
// - Writers write to "<path>.tmp<pid>" and rename it over path on success, so a
//   failed write never leaves a half-written file under the final name.
// - libpng errors longjmp back to the function that called libpng; everything
//   that is allocated after the setjmp() is reached through volatile pointers.
// - libtiff messages go to per-file handlers (TIFFOpenExt): errors become part
//   of the model_error() message, warnings are kept silent.
// - Size limit: at most MAX_PIXELS pixels and MAX_SIDE per side.
#define _GNU_SOURCE
#include <errno.h>
#include <png.h>
#include <setjmp.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <tiffio.h>
#include <unistd.h>

#include "model/internal.h"

#define MAX_SIDE   1000000L
#define MAX_PIXELS (1L << 28)

static bool check_size(const char *path, long w, long h)
{
    if (w <= 0 || h <= 0 || w > MAX_SIDE || h > MAX_SIDE || w * h > MAX_PIXELS) {
        model_error(path, 0, "image size %ldx%ld: must be positive and at most %ld pixels",
                    w, h, MAX_PIXELS);
        return false;
    }
    return true;
}

// meta: key, value pairs. PNG keywords are 1-79 printable Latin-1 characters
// without leading, trailing or double blanks; for TIFF "key: value" lines no
// key may hold ':' and nothing may hold a line break.
static bool check_meta(const char *path, const char *const *meta, bool png)
{
    for (int i = 0; meta && meta[i]; i += 2) {
        const char *k = meta[i], *v = meta[i + 1];
        if (!v) {
            model_error(path, 0, "metadata key '%s' has no value (the list is key, value, ..., NULL)", k);
            return false;
        }
        size_t n = strlen(k);
        bool bad = n == 0 || n > 79 || k[0] == ' ' || k[n - 1] == ' ' || strstr(k, "  ");
        for (const unsigned char *c = (const unsigned char *)k; *c; c++)
            if (*c < 32 || (*c > 126 && *c < 161) || (!png && *c == ':')) bad = true;
        if (bad) {
            model_error(path, 0, "metadata key '%s': use 1-79 printable characters%s", k,
                        png ? " without leading, trailing or double blanks" : " and no ':'");
            return false;
        }
        if (!png && strpbrk(v, "\r\n")) {
            model_error(path, 0, "metadata value of '%s' holds a line break (TIFF "
                        "ImageDescription keeps one 'key: value' line per key)", k);
            return false;
        }
    }
    return true;
}

static char *tmp_name(const char *path)
{
    size_t n = strlen(path) + 32;
    char *t = malloc(n);
    if (t) snprintf(t, n, "%s.tmp%ld", path, (long)getpid());
    return t;
}

static bool commit(const char *tmp, const char *path)
{
    if (rename(tmp, path) != 0) {
        model_error(path, 0, "cannot rename %s to it: %s", tmp, strerror(errno));
        unlink(tmp);
        return false;
    }
    return true;
}

// ---------------------------------------------------------------------------
// PNG

typedef struct {
    char msg[512];
} png_ctx_t;

static void png_err_fn(png_structp png, png_const_charp msg)
{
    png_ctx_t *ctx = png_get_error_ptr(png);
    snprintf(ctx->msg, sizeof ctx->msg, "%s", msg);
    png_longjmp(png, 1);
}

static void png_warn_fn(png_structp png, png_const_charp msg) { (void)png; (void)msg; }

bool model_png16_write(const char *path, int width, int height, const uint16_t *pix,
                       const char *const *meta)
{
    return model_png16_write_opts(path, width, height, pix, meta, NULL);
}

// The PNG stream itself (libpng's longjmp lands here): 16-bit pixels from
// pix16, or 8-bit ones from pix8. false with *err set.
static bool png_stream(FILE *f, const char *path, int width, int height, const uint16_t *pix16,
                       const uint8_t *pix8, const char *const *meta, int level, bool fast_filter, int *err)
{
    volatile int ntext = 0;   // read after setjmp()
    for (int i = 0; meta && meta[i]; i += 2) ntext++;
    png_ctx_t ctx = { "" };
    png_structp png = png_create_write_struct(PNG_LIBPNG_VER_STRING, &ctx, png_err_fn, png_warn_fn);
    png_infop info = png ? png_create_info_struct(png) : NULL;
    int bits = pix16 ? 16 : 8;
    png_bytep row = malloc((size_t)width * 2);
    png_textp text = calloc((size_t)ntext + 1, sizeof *text);
    volatile bool ok = false;
    if (!png || !info || !row || !text) {
        *err = ENOMEM;
        model_error(path, 0, "out of memory writing PNG");
        goto done;
    }
    errno = 0;
    if (setjmp(png_jmpbuf(png))) {
        *err = errno ? errno : EIO;   // the failing write's cause (ENOSPC for a full disk)
        model_error(path, 0, "cannot write PNG: %s (%s)", ctx.msg, strerror(*err));
        goto done;
    }
    png_init_io(png, f);
    png_set_IHDR(png, info, (png_uint_32)width, (png_uint_32)height, bits, PNG_COLOR_TYPE_GRAY,
                 PNG_INTERLACE_NONE, PNG_COMPRESSION_TYPE_DEFAULT, PNG_FILTER_TYPE_DEFAULT);
    if (level >= 0) png_set_compression_level(png, level);
    if (fast_filter) png_set_filter(png, PNG_FILTER_TYPE_BASE, PNG_FILTER_SUB);
    for (int i = 0; i < ntext; i++) {
        text[i].compression = PNG_TEXT_COMPRESSION_NONE;
        text[i].key = (png_charp)meta[2 * i];
        text[i].text = (png_charp)meta[2 * i + 1];
        text[i].text_length = strlen(meta[2 * i + 1]);
    }
    if (ntext) png_set_text(png, info, text, ntext);
    png_write_info(png, info);
    for (int y = 0; y < height && !pix16; y++) png_write_row(png, (png_const_bytep)(pix8 + (size_t)y * width));
    for (int y = 0; y < height && pix16; y++) {
        const uint16_t *src = pix16 + (size_t)y * width;
        for (int x = 0; x < width; x++) {   // PNG is big-endian
            row[2 * x] = (png_byte)(src[x] >> 8);
            row[2 * x + 1] = (png_byte)(src[x] & 0xff);
        }
        png_write_row(png, row);
    }
    png_write_end(png, info);
    ok = true;
done:
    png_destroy_write_struct(&png, &info);
    free(row);
    free(text);
    return ok;
}

static bool png_write_file(const char *path, int width, int height, const uint16_t *pix16, const uint8_t *pix8,
                           const char *const *meta, const model_png_options_t *opt);

bool model_png16_write_opts(const char *path, int width, int height, const uint16_t *pix,
                            const char *const *meta, const model_png_options_t *opt)
{
    return png_write_file(path, width, height, pix, NULL, meta, opt);
}

bool model_png8_write(const char *path, int width, int height, const uint8_t *pix, const char *const *meta)
{
    const model_png_options_t fast = { .compression_level = 1 };
    return png_write_file(path, width, height, NULL, pix, meta, &fast);
}

static bool png_write_file(const char *path, int width, int height, const uint16_t *pix16, const uint8_t *pix8,
                           const char *const *meta, const model_png_options_t *opt)
{
    const model_png_options_t defaults = { .compression_level = -1 };
    if (!opt) opt = &defaults;
    bool was_quiet = model_error_quiet_thread(opt->quiet);
    int err = 0;
    bool ok = false;
    char *tmp = NULL;
    FILE *f = NULL;
    if (!check_size(path, width, height) || !check_meta(path, meta, true)) {
        err = EINVAL;
        goto done;
    }
    if (!pix16 && !pix8) {
        MODEL_FAIL("model_png16_write: no pixels");
        err = EINVAL;
        goto done;
    }
    tmp = tmp_name(path);
    f = tmp ? fopen(tmp, "wb") : NULL;
    if (!f) {
        err = tmp ? errno : ENOMEM;
        model_error(path, 0, "cannot create %s: %s", tmp ? tmp : "a temporary file", strerror(err));
        goto done;
    }
    ok = png_stream(f, path, width, height, pix16, pix8, meta, opt->compression_level, opt->fast_filter, &err);
    if (ok && (fflush(f) != 0 || ferror(f) || (opt->fsync && fsync(fileno(f)) != 0))) {
        err = errno ? errno : EIO;
        model_error(path, 0, "write error: %s", strerror(err));
        ok = false;
    }
    if (fclose(f) != 0 && ok) {
        err = errno;
        model_error(path, 0, "write error: %s", strerror(err));
        ok = false;
    }
    if (ok) {
        ok = commit(tmp, path);
        if (!ok) err = errno;
    } else {
        unlink(tmp);
    }
done:
    free(tmp);
    model_error_quiet_thread(was_quiet);
    if (!ok) errno = err ? err : EIO;
    return ok;
}

// ---------------------------------------------------------------------------
// TIFF

typedef struct {
    char msg[512];
} tiff_ctx_t;

static int tiff_err_fn(TIFF *t, void *user, const char *module, const char *fmt, va_list ap)
{
    (void)t;
    tiff_ctx_t *ctx = user;
    if (ctx->msg[0]) return 1;   // keep the first error: it is the cause
    char m[400];
    vsnprintf(m, sizeof m, fmt, ap);
    snprintf(ctx->msg, sizeof ctx->msg, "%s%s%s", module ? module : "", module ? ": " : "", m);
    return 1;
}

static int tiff_warn_fn(TIFF *t, void *user, const char *module, const char *fmt, va_list ap)
{
    (void)t; (void)user; (void)module; (void)fmt; (void)ap;
    return 1;   // handled: silent
}

static TIFF *tiff_open(const char *path, const char *mode, tiff_ctx_t *ctx)
{
    TIFFOpenOptions *o = TIFFOpenOptionsAlloc();
    if (!o) return NULL;
    TIFFOpenOptionsSetErrorHandlerExtR(o, tiff_err_fn, ctx);
    TIFFOpenOptionsSetWarningHandlerExtR(o, tiff_warn_fn, ctx);
    TIFFOpenOptionsSetMaxSingleMemAlloc(o, (tmsize_t)MAX_PIXELS * 8);
    TIFF *t = TIFFOpenExt(path, mode, o);
    TIFFOpenOptionsFree(o);
    return t;
}

// "key: value\n" lines, or NULL for no metadata (caller frees).
static char *meta_description(const char *const *meta)
{
    if (!meta || !meta[0]) return NULL;
    size_t n = 1;
    for (int i = 0; meta[i]; i += 2) n += strlen(meta[i]) + strlen(meta[i + 1]) + 3;
    char *d = malloc(n), *p = d;
    if (!d) return NULL;
    for (int i = 0; meta[i]; i += 2) p += sprintf(p, "%s: %s\n", meta[i], meta[i + 1]);
    return d;
}

typedef enum { PAGE_FLOAT32, PAGE_INT32, PAGE_UINT8 } page_kind_t;

// One page (directory) of w x h pixels.
static bool tiff_page(TIFF *t, int w, int h, page_kind_t kind, const void *pix,
                      const char *page_name, int page, int npages, const char *desc)
{
    int bits = kind == PAGE_UINT8 ? 8 : 32;
    int fmt = kind == PAGE_FLOAT32 ? SAMPLEFORMAT_IEEEFP : kind == PAGE_INT32 ? SAMPLEFORMAT_INT
                                                                              : SAMPLEFORMAT_UINT;
    bool deflate = TIFFIsCODECConfigured(COMPRESSION_ADOBE_DEFLATE);
    TIFFSetField(t, TIFFTAG_IMAGEWIDTH, (uint32_t)w);
    TIFFSetField(t, TIFFTAG_IMAGELENGTH, (uint32_t)h);
    TIFFSetField(t, TIFFTAG_BITSPERSAMPLE, bits);
    TIFFSetField(t, TIFFTAG_SAMPLESPERPIXEL, 1);
    TIFFSetField(t, TIFFTAG_SAMPLEFORMAT, fmt);
    TIFFSetField(t, TIFFTAG_PHOTOMETRIC, PHOTOMETRIC_MINISBLACK);
    TIFFSetField(t, TIFFTAG_PLANARCONFIG, PLANARCONFIG_CONTIG);
    TIFFSetField(t, TIFFTAG_COMPRESSION, deflate ? COMPRESSION_ADOBE_DEFLATE : COMPRESSION_NONE);
    if (deflate)
        TIFFSetField(t, TIFFTAG_PREDICTOR,
                     kind == PAGE_FLOAT32 ? PREDICTOR_FLOATINGPOINT : PREDICTOR_HORIZONTAL);
    TIFFSetField(t, TIFFTAG_ROWSPERSTRIP, TIFFDefaultStripSize(t, 0));
    TIFFSetField(t, TIFFTAG_SOFTWARE, "refl " REFL_VERSION);
    if (desc) TIFFSetField(t, TIFFTAG_IMAGEDESCRIPTION, desc);
    if (page_name) TIFFSetField(t, TIFFTAG_PAGENAME, page_name);
    if (npages > 1) {
        TIFFSetField(t, TIFFTAG_SUBFILETYPE, FILETYPE_PAGE);
        TIFFSetField(t, TIFFTAG_PAGENUMBER, (uint16_t)page, (uint16_t)npages);
    }
    size_t rowbytes = (size_t)w * bits / 8;
    unsigned char *row = malloc(rowbytes);   // the predictor works in place: copy each row
    if (!row) return false;
    bool ok = true;
    for (int y = 0; y < h && ok; y++) {
        memcpy(row, (const unsigned char *)pix + (size_t)y * rowbytes, rowbytes);
        ok = TIFFWriteScanline(t, row, (uint32_t)y, 0) == 1;
    }
    free(row);
    return ok && TIFFWriteDirectory(t) == 1;
}

typedef struct {
    page_kind_t kind;
    const void *pix;
    const char *name;
} page_t;

static bool tiff_write_pages(const char *path, int w, int h, const page_t *pages, int npages,
                             const char *const *meta)
{
    if (!check_size(path, w, h) || !check_meta(path, meta, false)) return false;
    for (int i = 0; i < npages; i++)
        if (!pages[i].pix) {
            MODEL_FAIL("%s: no pixels for TIFF page %d", path, i);
            return false;
        }
    char *tmp = tmp_name(path), *desc = meta_description(meta);
    tiff_ctx_t ctx = { "" };
    TIFF *t = tmp ? tiff_open(tmp, "w", &ctx) : NULL;
    bool ok = false;
    if (!t) {
        model_error(path, 0, "cannot create %s: %s", tmp ? tmp : "a temporary file",
                    ctx.msg[0] ? ctx.msg : strerror(errno));
        goto done;
    }
    if (meta && meta[0] && !desc) {
        model_error(path, 0, "out of memory");
        goto done;
    }
    ok = true;
    for (int i = 0; i < npages && ok; i++)
        ok = tiff_page(t, w, h, pages[i].kind, pages[i].pix, pages[i].name, i, npages,
                       i == 0 ? desc : NULL);
    if (!ok) model_error(path, 0, "cannot write TIFF: %s", ctx.msg[0] ? ctx.msg : "out of memory");
done:
    if (t) {
        TIFFClose(t);
        if (ok && ctx.msg[0]) {
            model_error(path, 0, "cannot write TIFF: %s", ctx.msg);
            ok = false;
        }
        if (ok) ok = commit(tmp, path);
        else unlink(tmp);
    }
    free(tmp);
    free(desc);
    return ok;
}

bool model_tiff_write_float(const char *path, int width, int height, const float *pix,
                            const char *const *meta)
{
    page_t p = { PAGE_FLOAT32, pix, NULL };
    return tiff_write_pages(path, width, height, &p, 1, meta);
}

bool model_tiff_write_info(const char *path, int width, int height, const float *P,
                           const int32_t *face, const uint8_t *lit, int nlamps,
                           const char *const *lamp_names, const char *const *meta)
{
    if (nlamps < 0 || nlamps > 60000 || (nlamps > 0 && !lit)) {
        MODEL_FAIL("%s: model_tiff_write_info: bad lamp planes (nlamps %d)", path, nlamps);
        return false;
    }
    int npages = 2 + nlamps;
    page_t *pages = calloc((size_t)npages, sizeof *pages);
    char (*names)[96] = calloc((size_t)nlamps + 1, sizeof *names);
    bool ok = false;
    if (!pages || !names) {
        model_error(path, 0, "out of memory");
        goto done;
    }
    pages[0] = (page_t){ PAGE_FLOAT32, P, "P" };
    pages[1] = (page_t){ PAGE_INT32, face, "face" };
    for (int i = 0; i < nlamps; i++) {
        if (lamp_names && lamp_names[i]) snprintf(names[i], sizeof names[i], "lit %s", lamp_names[i]);
        else snprintf(names[i], sizeof names[i], "lit %d", i);
        pages[2 + i] = (page_t){ PAGE_UINT8, lit + (size_t)i * width * height, names[i] };
    }
    ok = tiff_write_pages(path, width, height, pages, npages, meta);
done:
    free(pages);
    free(names);
    return ok;
}

double model_image_bilinear(const float *P, int W, int H, double x, double y, bool *inside)
{
    if (!(x >= 0 && y >= 0 && x <= W - 1.001 && y <= H - 1.001)) {
        *inside = false;
        return 0;
    }
    int x0 = (int)x, y0 = (int)y;
    double fx = x - x0, fy = y - y0;
    const float *r0 = P + (size_t)y0 * W + x0, *r1 = r0 + W;
    return (1 - fy) * ((1 - fx) * r0[0] + fx * r0[1]) + fy * ((1 - fx) * r1[0] + fx * r1[1]);
}
