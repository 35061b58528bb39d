// model/image/read.c — the one image reader: PNG (libpng; grey, grey+alpha,
// RGB, RGBA, palette; 1-16 bits), JPEG (libjpeg-turbo; grey or colour) and
// TIFF (libtiff; grey or RGB(A), integer 8/16/32 bits or float 32/64, strips,
// contiguous or planar), told apart by their first bytes, never by the name.
//
// - Every decoder works on the file's bytes in memory (the fuzz corpus feeds
//   them directly): libpng through a read callback, libjpeg through
//   jpeg_mem_src, libtiff through TIFFClientOpenExt.
// - Colour becomes one value per pixel by model_image_channel(): Rec. 709
//   luma weights (0.2126 R + 0.7152 G + 0.0722 B) on the stored (encoded)
//   values, no transfer curve undone; or one of R, G, B. Alpha is ignored.
// - libpng and libjpeg errors longjmp back to the decoding function; what is
//   allocated after the setjmp() is reached through volatile pointers. A JPEG
//   warning (libjpeg's "premature end of data", corrupt Huffman data) is an
//   error here: the decoded image would be partly grey filler.
// - Size limit: at most MAX_PIXELS pixels and MAX_SIDE per side.
#define _GNU_SOURCE
#include <dirent.h>
#include <errno.h>
#include <glib.h>
#include <glob.h>
#include <stdio.h>   // before jpeglib.h, which uses FILE
#include <jpeglib.h>
#include <jerror.h>
#include <png.h>
#include <setjmp.h>
#include <stdarg.h>
#include <stdatomic.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <tiffio.h>

#include "model/internal.h"

#define MAX_SIDE   1000000L
#define MAX_PIXELS (1L << 28)

static bool size_ok(const char *name, long w, long h)
{
    if (w <= 0 || h <= 0 || w > MAX_SIDE || h > MAX_SIDE || w * h > MAX_PIXELS) {
        model_error(name, 0, "image size %ldx%ld: must be positive and at most %ld pixels", w, h, MAX_PIXELS);
        return false;
    }
    return true;
}

// ---------------------------------------------------------------------------
// Channels

static _Atomic int channel_default = MODEL_CHANNEL_LUMA;

void model_image_set_channel(model_channel_t ch) { atomic_store(&channel_default, (int)ch); }
model_channel_t model_image_channel(void) { return (model_channel_t)atomic_load(&channel_default); }

bool model_channel_parse(const char *s, model_channel_t *out)
{
    static const char *names[] = { "luma", "r", "g", "b" };
    for (int i = 0; s && i < 4; i++)
        if (!strcmp(s, names[i])) {
            *out = (model_channel_t)i;
            return true;
        }
    return false;
}

const char *model_channel_name(model_channel_t ch)
{
    return ch == MODEL_CHANNEL_R ? "r" : ch == MODEL_CHANNEL_G ? "g" : ch == MODEL_CHANNEL_B ? "b" : "luma";
}

static inline float mix(double r, double g, double b, model_channel_t ch)
{
    switch (ch) {
    case MODEL_CHANNEL_R: return (float)r;
    case MODEL_CHANNEL_G: return (float)g;
    case MODEL_CHANNEL_B: return (float)b;
    default: return (float)(MODEL_LUMA_R * r + MODEL_LUMA_G * g + MODEL_LUMA_B * b);
    }
}

// ---------------------------------------------------------------------------
// PNG

typedef struct {
    const unsigned char *p;
    size_t n, pos;
    char msg[512];
} png_src_t;

static void png_err_fn(png_structp png, png_const_charp msg)
{
    png_src_t *src = png_get_error_ptr(png);
    snprintf(src->msg, sizeof src->msg, "%s", msg);
    png_longjmp(png, 1);
}

static void png_warn_fn(png_structp png, png_const_charp msg) { (void)png; (void)msg; }

static void png_mem_read(png_structp png, png_bytep out, size_t n)
{
    png_src_t *src = png_get_io_ptr(png);
    if (n > src->n - src->pos) png_error(png, "the file ends early (truncated)");
    memcpy(out, src->p + src->pos, n);
    src->pos += n;
}

static float *png_decode(const unsigned char *data, size_t len, const char *name, model_channel_t ch, int *width,
                         int *height, model_meta_t *meta)
{
    if (len < 8 || png_sig_cmp(data, 0, 8) != 0) {
        model_error(name, 0, "not a PNG file (no PNG signature)");
        return NULL;
    }
    png_src_t src = { .p = data, .n = len, .pos = 8 };
    png_structp png = png_create_read_struct(PNG_LIBPNG_VER_STRING, &src, png_err_fn, png_warn_fn);
    png_infop info = png ? png_create_info_struct(png) : NULL;
    // allocated after setjmp(): volatile, so that their values survive a longjmp
    png_bytep volatile buf = NULL;
    png_bytepp volatile rows = NULL;
    float *volatile out = NULL;
    float *res = NULL;
    if (!png || !info) {
        model_error(name, 0, "out of memory reading PNG");
        goto done;
    }
    if (setjmp(png_jmpbuf(png))) {
        model_error(name, 0, "corrupt or truncated PNG: %s", src.msg);
        goto done;
    }
    png_set_read_fn(png, &src, png_mem_read);
    png_set_sig_bytes(png, 8);
    png_set_user_limits(png, MAX_SIDE, MAX_SIDE);
    png_read_info(png, info);
    png_uint_32 w, h;
    int depth, ctype, interlace;
    png_get_IHDR(png, info, &w, &h, &depth, &ctype, &interlace, NULL, NULL);
    if (!size_ok(name, (long)w, (long)h)) goto done;
    if (ctype == PNG_COLOR_TYPE_PALETTE) png_set_palette_to_rgb(png);   // 8-bit RGB, tRNS ignored
    else if (depth < 8) png_set_packing(png);   // 1, 2, 4 bits grey: one byte per pixel, values kept
    if (ctype & PNG_COLOR_MASK_ALPHA) png_set_strip_alpha(png);
    png_set_interlace_handling(png);
    png_read_update_info(png, info);
    int nch = png_get_channels(png, info), bd = png_get_bit_depth(png, info);
    size_t bpp = bd == 16 ? 2 : 1, rowbytes = png_get_rowbytes(png, info);
    if ((nch != 1 && nch != 3) || rowbytes != (size_t)w * bpp * (size_t)nch) {
        model_error(name, 0, "unexpected PNG layout (%d channels, %zu bytes per row for %u pixels)", nch, rowbytes,
                    (unsigned)w);
        goto done;
    }
    // deflate packs at most ~1030 bytes into one: a header that claims more is damaged
    if ((double)rowbytes * h > 1100.0 * (double)len) {
        model_error(name, 0, "a PNG of %ux%u pixels cannot fit in its %zu bytes: truncated or damaged", (unsigned)w,
                    (unsigned)h, len);
        goto done;
    }
    buf = malloc(rowbytes * h);
    rows = malloc(h * sizeof *rows);
    out = malloc((size_t)w * h * sizeof *out);
    if (!buf || !rows || !out) {
        model_error(name, 0, "out of memory for a %ux%u image", (unsigned)w, (unsigned)h);
        goto done;
    }
    for (png_uint_32 y = 0; y < h; y++) rows[y] = buf + y * rowbytes;
    png_read_image(png, rows);
    png_read_end(png, meta ? info : NULL);
    if (meta) {
        png_textp text = NULL;
        int ntext = png_get_text(png, info, &text, NULL);
        for (int i = 0; i < ntext; i++)
            if (text[i].key && text[i].text) model_meta_add(meta, text[i].key, "%s", text[i].text);
    }
    for (size_t i = 0; i < (size_t)w * h; i++) {
        double v[3];
        for (int c = 0; c < nch; c++) {   // PNG is big-endian
            const png_byte *s = buf + (i * (size_t)nch + (size_t)c) * bpp;
            v[c] = bpp == 2 ? (s[0] << 8 | s[1]) : s[0];
        }
        out[i] = nch == 1 ? (float)v[0] : mix(v[0], v[1], v[2], ch);
    }
    *width = (int)w;
    *height = (int)h;
    res = out;
    out = NULL;
done:
    png_destroy_read_struct(&png, &info, NULL);
    free(buf);
    free(rows);
    free(out);
    return res;
}

// ---------------------------------------------------------------------------
// JPEG

typedef struct {
    struct jpeg_error_mgr pub;
    jmp_buf jb;
    char msg[JMSG_LENGTH_MAX];
} jpeg_err_t;

static void jpeg_exit_fn(j_common_ptr c)
{
    jpeg_err_t *e = (jpeg_err_t *)c->err;
    c->err->format_message(c, e->msg);
    longjmp(e->jb, 1);
}

// Warnings (level -1) of damaged data end the decoding at once (libjpeg would
// go on with grey filler); the others (an unknown JFIF revision, extraneous
// bytes before a marker) are harmless and silent.
static void jpeg_emit_fn(j_common_ptr c, int level)
{
    if (level >= 0) return;
    int code = c->err->msg_code;
    if (code == JWRN_JPEG_EOF || code == JWRN_HIT_MARKER || code == JWRN_HUFF_BAD_CODE ||
        code == JWRN_ARITH_BAD_CODE || code == JWRN_MUST_RESYNC || code == JWRN_NOT_SEQUENTIAL)
        jpeg_exit_fn(c);
}

static float *jpeg_decode(const unsigned char *data, size_t len, const char *name, model_channel_t ch, int *width,
                          int *height)
{
    struct jpeg_decompress_struct cinfo;
    jpeg_err_t jerr = { 0 };
    cinfo.err = jpeg_std_error(&jerr.pub);
    jerr.pub.error_exit = jpeg_exit_fn;
    jerr.pub.emit_message = jpeg_emit_fn;
    JSAMPLE *volatile row = NULL;
    float *volatile out = NULL;
    float *res = NULL;
    if (setjmp(jerr.jb)) {
        model_error(name, 0, "corrupt or truncated JPEG: %s", jerr.msg);
        goto done;
    }
    jpeg_create_decompress(&cinfo);
    jpeg_mem_src(&cinfo, data, (unsigned long)len);
    jpeg_read_header(&cinfo, TRUE);
    if (!size_ok(name, (long)cinfo.image_width, (long)cinfo.image_height)) goto done;
    int nch;
    if (cinfo.jpeg_color_space == JCS_GRAYSCALE) {
        cinfo.out_color_space = JCS_GRAYSCALE;
        nch = 1;
    } else if (cinfo.jpeg_color_space == JCS_YCbCr || cinfo.jpeg_color_space == JCS_RGB) {
        cinfo.out_color_space = JCS_RGB;
        nch = 3;
    } else {
        model_error(name, 0, "a CMYK or YCCK JPEG (colour space %d): save it as RGB or greyscale",
                    (int)cinfo.jpeg_color_space);
        goto done;
    }
    jpeg_start_decompress(&cinfo);
    size_t w = cinfo.output_width, h = cinfo.output_height;
    row = malloc(w * (size_t)nch);
    out = malloc(w * h * sizeof *out);
    if (!row || !out) {
        model_error(name, 0, "out of memory for a %zux%zu image", w, h);
        goto done;
    }
    while (cinfo.output_scanline < h) {
        size_t y = cinfo.output_scanline;
        JSAMPROW r = row;
        if (jpeg_read_scanlines(&cinfo, &r, 1) != 1) break;
        float *o = out + y * w;
        for (size_t x = 0; x < w; x++)
            o[x] = nch == 1 ? row[x] : mix(row[3 * x], row[3 * x + 1], row[3 * x + 2], ch);
    }
    jpeg_finish_decompress(&cinfo);
    *width = (int)w;
    *height = (int)h;
    res = out;
    out = NULL;
done:
    jpeg_destroy_decompress(&cinfo);
    free(row);
    free(out);
    return res;
}

// ---------------------------------------------------------------------------
// TIFF, read from memory

typedef struct {
    const unsigned char *p;
    size_t n, pos;
    const char *name;
    char msg[512];
} tiff_src_t;

static int tiff_err_fn(TIFF *t, void *user, const char *module, const char *fmt, va_list ap)
{
    (void)t;
    tiff_src_t *src = user;
    if (src->msg[0]) return 1;   // keep the first error: it is the cause
    char m[400];
    vsnprintf(m, sizeof m, fmt, ap);
    // the file is named once, by the caller: not as libtiff's module nor at the message's start
    size_t nn = strlen(src->name);
    const char *mm = !strncmp(m, src->name, nn) && !strncmp(m + nn, ": ", 2) ? m + nn + 2 : m;
    if (module && !strcmp(module, src->name)) module = NULL;
    snprintf(src->msg, sizeof src->msg, "%s%s%s", module ? module : "", module ? ": " : "", mm);
    return 1;
}

static int tiff_warn_fn(TIFF *t, void *user, const char *module, const char *fmt, va_list ap)
{
    (void)t; (void)user; (void)module; (void)fmt; (void)ap;
    return 1;   // handled: silent
}

static tmsize_t tiff_mem_read(thandle_t h, void *buf, tmsize_t n)
{
    tiff_src_t *s = (tiff_src_t *)h;
    size_t k = s->pos < s->n ? s->n - s->pos : 0;
    if ((size_t)n < k) k = (size_t)n;
    memcpy(buf, s->p + s->pos, k);
    s->pos += k;
    return (tmsize_t)k;
}

static tmsize_t tiff_mem_write(thandle_t h, void *buf, tmsize_t n) { (void)h; (void)buf; (void)n; return -1; }

static toff_t tiff_mem_seek(thandle_t h, toff_t off, int whence)
{
    tiff_src_t *s = (tiff_src_t *)h;
    uint64_t base = whence == SEEK_CUR ? s->pos : whence == SEEK_END ? s->n : 0;
    if (off > UINT64_MAX - base) return (toff_t)-1;
    s->pos = (size_t)(base + off);   // may be past the end: reads there return nothing
    return (toff_t)s->pos;
}

static int tiff_mem_close(thandle_t h) { (void)h; return 0; }
static toff_t tiff_mem_size(thandle_t h) { return (toff_t)((tiff_src_t *)h)->n; }
static int tiff_mem_map(thandle_t h, void **base, toff_t *size) { (void)h; (void)base; (void)size; return 0; }
static void tiff_mem_unmap(thandle_t h, void *base, toff_t size) { (void)h; (void)base; (void)size; }

static double tiff_sample(const unsigned char *p, int bps, int fmt)
{
    if (fmt == SAMPLEFORMAT_IEEEFP) {
        if (bps == 32) { float a; memcpy(&a, p, 4); return a; }
        double a; memcpy(&a, p, 8); return a;
    }
    if (fmt == SAMPLEFORMAT_INT) {
        if (bps == 8) return *(const int8_t *)p;
        if (bps == 16) { int16_t a; memcpy(&a, p, 2); return a; }
        int32_t a; memcpy(&a, p, 4); return a;
    }
    if (bps == 8) return *p;
    if (bps == 16) { uint16_t a; memcpy(&a, p, 2); return a; }
    uint32_t a; memcpy(&a, p, 4); return a;
}

// The first page's layout; false with the reason.
static bool tiff_layout(TIFF *t, const char *name, uint32_t *w, uint32_t *h, int *spp_, int *bps_, int *fmt_,
                        bool *planar, int *nch)
{
    uint16_t spp = 1, bps = 1, fmt = SAMPLEFORMAT_UINT, pc = PLANARCONFIG_CONTIG, photo = PHOTOMETRIC_MINISBLACK;
    TIFFGetField(t, TIFFTAG_IMAGEWIDTH, w);
    TIFFGetField(t, TIFFTAG_IMAGELENGTH, h);
    TIFFGetFieldDefaulted(t, TIFFTAG_SAMPLESPERPIXEL, &spp);
    TIFFGetFieldDefaulted(t, TIFFTAG_BITSPERSAMPLE, &bps);
    TIFFGetFieldDefaulted(t, TIFFTAG_SAMPLEFORMAT, &fmt);
    TIFFGetFieldDefaulted(t, TIFFTAG_PLANARCONFIG, &pc);
    if (!TIFFGetField(t, TIFFTAG_PHOTOMETRIC, &photo)) photo = spp >= 3 ? PHOTOMETRIC_RGB : PHOTOMETRIC_MINISBLACK;
    if (!size_ok(name, (long)*w, (long)*h)) return false;
    if (photo == PHOTOMETRIC_RGB && spp >= 3 && spp <= 4) {
        *nch = 3;
    } else if (photo == PHOTOMETRIC_MINISBLACK && spp >= 1 && spp <= 2) {
        *nch = 1;   // a second sample is alpha: ignored
    } else {
        model_error(name, 0, "TIFF with %u samples per pixel, photometric interpretation %u: expected grey "
                    "(MinIsBlack, 1 sample, or 2 with alpha) or RGB (3 samples, or 4 with alpha)", spp, photo);
        return false;
    }
    if (TIFFIsTiled(t)) {
        model_error(name, 0, "tiled TIFF is not supported; save it with strips");
        return false;
    }
    bool known = (fmt == SAMPLEFORMAT_IEEEFP && (bps == 32 || bps == 64)) ||
                 ((fmt == SAMPLEFORMAT_UINT || fmt == SAMPLEFORMAT_INT) && (bps == 8 || bps == 16 || bps == 32));
    if (!known) {
        model_error(name, 0, "TIFF samples of %u bits, format %u: expected float 32/64 or integer 8/16/32 bits", bps,
                    fmt);
        return false;
    }
    *planar = pc == PLANARCONFIG_SEPARATE && spp > 1;
    size_t expect = (size_t)*w * bps / 8 * (*planar ? 1 : spp);
    if (TIFFScanlineSize(t) != (tmsize_t)expect) {
        model_error(name, 0, "unexpected TIFF layout (%ld bytes per row)", (long)TIFFScanlineSize(t));
        return false;
    }
    *spp_ = spp;
    *bps_ = bps;
    *fmt_ = fmt;
    return true;
}

static float *tiff_decode(const unsigned char *data, size_t len, const char *name, model_channel_t ch, int *width,
                          int *height)
{
    tiff_src_t src = { .p = data, .n = len, .name = name };
    TIFFOpenOptions *o = TIFFOpenOptionsAlloc();
    TIFF *t = NULL;
    if (o) {
        TIFFOpenOptionsSetErrorHandlerExtR(o, tiff_err_fn, &src);
        TIFFOpenOptionsSetWarningHandlerExtR(o, tiff_warn_fn, &src);
        TIFFOpenOptionsSetMaxSingleMemAlloc(o, (tmsize_t)MAX_PIXELS * 8);
        t = TIFFClientOpenExt(name, "rm", (thandle_t)&src, tiff_mem_read, tiff_mem_write, tiff_mem_seek,
                              tiff_mem_close, tiff_mem_size, tiff_mem_map, tiff_mem_unmap, o);
        TIFFOpenOptionsFree(o);
    }
    unsigned char *rows = NULL;
    float *out = NULL, *res = NULL;
    if (!t) {
        model_error(name, 0, "not a readable TIFF: %s", src.msg[0] ? src.msg : "unknown error");
        goto done;
    }
    uint32_t w = 0, h = 0;
    int spp, bps, fmt, nch;
    bool planar;
    if (!tiff_layout(t, name, &w, &h, &spp, &bps, &fmt, &planar, &nch)) goto done;
    size_t sl = (size_t)TIFFScanlineSize(t), step = (size_t)bps / 8;
    rows = malloc(sl);
    out = malloc((size_t)w * h * sizeof *out);
    if (!rows || !out) {
        model_error(name, 0, "out of memory for a %ux%u image", w, h);
        goto done;
    }
    // Planar: plane by plane, each read from its first row on (compressed
    // strips cannot be read out of order), its share added to the pixels.
    double wgt[3] = { MODEL_LUMA_R, MODEL_LUMA_G, MODEL_LUMA_B };
    if (ch != MODEL_CHANNEL_LUMA)
        for (int c = 0; c < 3; c++) wgt[c] = c == (int)ch - 1;
    if (nch == 1) wgt[0] = 1;
    for (int plane = 0; plane < (planar ? nch : 1); plane++) {
        for (uint32_t y = 0; y < h; y++) {
            if (TIFFReadScanline(t, rows, y, (uint16_t)plane) != 1) {
                model_error(name, 0, "corrupt or truncated TIFF at row %u: %s", y, src.msg[0] ? src.msg : "read error");
                goto done;
            }
            float *op = out + (size_t)y * w;
            for (uint32_t x = 0; x < w; x++) {
                if (planar) {
                    double v = wgt[plane] * tiff_sample(rows + x * step, bps, fmt);
                    op[x] = plane ? (float)(op[x] + v) : (float)v;
                    continue;
                }
                double v[3];
                for (int c = 0; c < nch; c++)
                    v[c] = tiff_sample(rows + ((size_t)x * (size_t)spp + (size_t)c) * step, bps, fmt);
                op[x] = nch == 1 ? (float)v[0] : mix(v[0], v[1], v[2], ch);
            }
        }
    }
    *width = (int)w;
    *height = (int)h;
    res = out;
    out = NULL;
done:
    if (t) TIFFClose(t);
    free(rows);
    free(out);
    return res;
}

// ---------------------------------------------------------------------------
// The entry points

model_image_format_t model_image_format(const void *data, size_t len)
{
    const unsigned char *s = data;
    if (len >= 8 && !memcmp(s, "\x89PNG\r\n\x1a\n", 8)) return MODEL_IMAGE_PNG;
    if (len >= 3 && s[0] == 0xff && s[1] == 0xd8 && s[2] == 0xff) return MODEL_IMAGE_JPEG;
    if (len >= 4 && ((s[0] == 'I' && s[1] == 'I' && (s[2] == 42 || s[2] == 43) && s[3] == 0) ||
                     (s[0] == 'M' && s[1] == 'M' && s[2] == 0 && (s[3] == 42 || s[3] == 43))))
        return MODEL_IMAGE_TIFF;
    return MODEL_IMAGE_UNKNOWN;
}

float *model_image_decode(const void *data, size_t len, const char *name, model_channel_t ch, int *width,
                          int *height, model_meta_t *meta)
{
    if (!name) name = "(image)";
    if (!data && len) {
        MODEL_FAIL("%s: no data", name);
        return NULL;
    }
    switch (model_image_format(data, len)) {
    case MODEL_IMAGE_PNG: return png_decode(data, len, name, ch, width, height, meta);
    case MODEL_IMAGE_JPEG: return jpeg_decode(data, len, name, ch, width, height);
    case MODEL_IMAGE_TIFF: return tiff_decode(data, len, name, ch, width, height);
    default: break;
    }
    if (len == 0) model_error(name, 0, "an empty file, not an image");
    else
        model_error(name, 0, "not an image refl reads (its first bytes are those of no PNG, JPEG or TIFF file)");
    return NULL;
}

float *model_image_read(const char *path, model_channel_t ch, int *width, int *height, model_meta_t *meta)
{
    // the first bytes first: a large file that is no image (a video beside the photos) is not read whole
    FILE *f = fopen(path, "rb");
    unsigned char head[16];
    size_t got = f ? fread(head, 1, sizeof head, f) : 0;
    if (f) fclose(f);
    if (f && got > 0 && model_image_format(head, got) == MODEL_IMAGE_UNKNOWN)
        return model_image_decode(head, got, path, ch, width, height, meta);   // the error saying why
    size_t len = 0;
    char *data = model_read_file(path, &len);
    if (!data) return NULL;
    float *out = model_image_decode(data, len, path, ch, width, height, meta);
    free(data);
    return out;
}

float *model_image_read_float(const char *path, int *width, int *height)
{
    return model_image_read(path, model_image_channel(), width, height, NULL);
}

bool model_tiff_read_float(const char *path, int *width, int *height, float **pix)
{
    *pix = model_image_read_float(path, width, height);
    return *pix != NULL;
}

// 16-bit values: grey kept as is, colour mixed and rounded (within 0..65535).
static bool read_u16(const char *path, int *width, int *height, uint16_t **pix, model_meta_t *meta)
{
    int w = 0, h = 0;
    float *f = model_image_read(path, model_image_channel(), &w, &h, meta);
    *pix = NULL;
    if (!f) return false;
    uint16_t *o = malloc((size_t)w * h * sizeof *o);
    if (!o) {
        free(f);
        model_error(path, 0, "out of memory");
        return false;
    }
    for (size_t i = 0; i < (size_t)w * h; i++) {
        float v = f[i];
        o[i] = !(v > 0) ? 0 : v >= 65535 ? 65535 : (uint16_t)lrintf(v);
    }
    free(f);
    *width = w;
    *height = h;
    *pix = o;
    return true;
}

bool model_png_read(const char *path, int *width, int *height, uint16_t **pix)
{
    return read_u16(path, width, height, pix, NULL);
}

bool model_png_read_meta(const char *path, int *width, int *height, uint16_t **pix, model_meta_t *meta)
{
    return read_u16(path, width, height, pix, meta);
}

// ---------------------------------------------------------------------------
// Lists of image files

static int cmp_str(const void *a, const void *b) { return strcmp(*(char *const *)a, *(char *const *)b); }

bool model_image_list(const char *spec, char ***paths, int *n)
{
    *paths = NULL;
    *n = 0;
    struct stat st;
    if (!spec || !*spec) {
        model_error(NULL, 0, "no image directory or pattern given");
        return false;
    }
    GPtrArray *a = g_ptr_array_new();
    if (stat(spec, &st) == 0 && S_ISDIR(st.st_mode)) {
        DIR *d = opendir(spec);
        if (!d) {
            model_error(spec, 0, "cannot read the directory: %s", strerror(errno));
            g_ptr_array_free(a, TRUE);
            return false;
        }
        for (struct dirent *e; (e = readdir(d));) {
            if (e->d_name[0] == '.') continue;   // hidden files, . and ..
            char *p = g_build_filename(spec, e->d_name, NULL);
            if (stat(p, &st) == 0 && S_ISREG(st.st_mode)) g_ptr_array_add(a, p);
            else g_free(p);
        }
        closedir(d);
    } else {
        glob_t gl;
        int e = glob(spec, 0, NULL, &gl);
        for (size_t i = 0; e == 0 && i < gl.gl_pathc; i++)
            if (stat(gl.gl_pathv[i], &st) == 0 && S_ISREG(st.st_mode)) g_ptr_array_add(a, g_strdup(gl.gl_pathv[i]));
        if (e == 0) globfree(&gl);
    }
    if (a->len == 0) {
        model_error(spec, 0, "%s", stat(spec, &st) == 0 ? "the directory holds no files"
                                                         : "no such directory, and as a pattern it matches no file");
        g_ptr_array_free(a, TRUE);
        return false;
    }
    qsort(a->pdata, a->len, sizeof(char *), cmp_str);
    *n = (int)a->len;
    *paths = (char **)g_ptr_array_free(a, FALSE);
    return true;
}

void model_image_list_free(char **paths, int n)
{
    for (int i = 0; paths && i < n; i++) g_free(paths[i]);
    g_free(paths);
}
