// tests/test_model_image.c — image files: PNG and TIFF round trips with metadata,
// the multi-page info TIFF, other sample types, and clean errors on damaged
// files.
#define _GNU_SOURCE
#include <glib.h>
#include <png.h>
#include <stdio.h>   // before jpeglib.h, which uses FILE
#include <jpeglib.h>
#include <stdlib.h>
#include <tiffio.h>
#include <unistd.h>
#include <zlib.h>

#include "model/internal.h"
#include "tests/test.h"

static void truncate_copy(const char *src, const char *dst, double frac, long flip_at)
{
    size_t len;
    char *buf = model_read_file(src, &len);
    if (!buf) return;
    if (flip_at >= 0 && (size_t)flip_at < len) buf[flip_at] ^= 0x5a;
    FILE *f = fopen(dst, "wb");
    if (f) {
        fwrite(buf, 1, (size_t)(len * frac), f);
        fclose(f);
    }
    free(buf);
}

// libtiff quiet for the test's own reading (the product uses per-file handlers)
static TIFF *test_tiff_open(const char *path)
{
    TIFFSetWarningHandler(NULL);
    return TIFFOpen(path, "r");
}

TEST(image_png16_round_trip_with_metadata)
{
    enum { W = 301, H = 203 };
    uint16_t *pix = malloc(W * H * sizeof *pix);
    for (int i = 0; i < W * H; i++) pix[i] = (uint16_t)((uint32_t)i * 7919u);
    pix[0] = 0;
    pix[1] = 65535;
    const char *meta[] = { "camera", "cam0 serial 1234", "exposure_us", "12000",
                           "Description", "rendered by refl; kc 1.5", NULL };
    const char *path = test_path("a.png");
    CHECK(model_png16_write(path, W, H, pix, meta));
    int w = 0, h = 0;
    uint16_t *back = NULL;
    CHECK(model_png_read(path, &w, &h, &back));
    CHECK(w == W && h == H);
    if (back) CHECK(memcmp(pix, back, W * H * sizeof *pix) == 0);
    free(back);

    // the tEXt chunks, read with libpng itself; and the header says 16-bit grey
    FILE *f = fopen(path, "rb");
    CHECK(f != NULL);
    if (f) {
        png_structp png = png_create_read_struct(PNG_LIBPNG_VER_STRING, NULL, NULL, NULL);
        png_infop info = png_create_info_struct(png);
        if (setjmp(png_jmpbuf(png)) == 0) {
            png_init_io(png, f);
            png_read_info(png, info);
            CHECK(png_get_bit_depth(png, info) == 16);
            CHECK(png_get_color_type(png, info) == PNG_COLOR_TYPE_GRAY);
            png_textp text;
            int n = 0;
            png_get_text(png, info, &text, &n);
            CHECK(n == 3);
            for (int i = 0; i < n && i < 3; i++) {
                CHECK(strcmp(text[i].key, meta[2 * i]) == 0);
                CHECK(strcmp(text[i].text, meta[2 * i + 1]) == 0);
            }
        } else {
            CHECK(!"libpng failed reading the written file");
        }
        png_destroy_read_struct(&png, &info, NULL);
        fclose(f);
    }
    // no metadata at all is fine too
    CHECK(model_png16_write(test_path("b.png"), W, H, pix, NULL));
    free(pix);
}

// A PNG written with libpng directly (8-bit grey, or colour / palette).
static bool write_png_raw(const char *path, int w, int h, int depth, int ctype, const uint8_t *data,
                          int channels)
{
    FILE *f = fopen(path, "wb");
    if (!f) return false;
    png_structp png = png_create_write_struct(PNG_LIBPNG_VER_STRING, NULL, NULL, NULL);
    png_infop info = png_create_info_struct(png);
    bool ok = false;
    if (setjmp(png_jmpbuf(png)) == 0) {
        png_init_io(png, f);
        png_set_IHDR(png, info, w, h, depth, ctype, PNG_INTERLACE_NONE, PNG_COMPRESSION_TYPE_DEFAULT,
                     PNG_FILTER_TYPE_DEFAULT);
        if (ctype == PNG_COLOR_TYPE_PALETTE) {
            png_color pal[2] = { { 0, 0, 0 }, { 255, 0, 0 } };
            png_set_PLTE(png, info, pal, 2);
        }
        png_write_info(png, info);
        size_t stride = (size_t)w * channels * (depth == 16 ? 2 : 1);
        for (int y = 0; y < h; y++) png_write_row(png, (png_const_bytep)(data + (size_t)y * stride));
        png_write_end(png, info);
        ok = true;
    }
    png_destroy_write_struct(&png, &info);
    fclose(f);
    return ok;
}

TEST(image_png8_and_colour)
{
    enum { W = 37, H = 11 };
    uint8_t g[W * H], rgb[W * H * 3], idx[W * H];
    for (int i = 0; i < W * H; i++) {
        g[i] = (uint8_t)(i * 13);
        rgb[3 * i] = rgb[3 * i + 1] = rgb[3 * i + 2] = g[i];
        idx[i] = i & 1;
    }
    const char *p8 = test_path("g8.png");
    CHECK(write_png_raw(p8, W, H, 8, PNG_COLOR_TYPE_GRAY, g, 1));
    int w, h;
    uint16_t *back = NULL;
    CHECK(model_png_read(p8, &w, &h, &back));
    CHECK(w == W && h == H);
    if (back) {
        bool same = true;
        for (int i = 0; i < W * H; i++) same = same && back[i] == g[i];   // kept as is
        CHECK(same);
    }
    free(back);

    // colour (grey values in RGB): luma of equal channels is the grey value
    const char *prgb = test_path("rgb.png");
    CHECK(write_png_raw(prgb, W, H, 8, PNG_COLOR_TYPE_RGB, rgb, 3));
    back = NULL;
    CHECK(model_png_read(prgb, &w, &h, &back));
    if (back) {
        bool same = true;
        for (int i = 0; i < W * H; i++) same = same && back[i] == g[i];
        CHECK(same);
    }
    free(back);

    // a palette PNG: expanded to RGB; black and red (255, 0, 0)
    const char *ppal = test_path("pal.png");
    CHECK(write_png_raw(ppal, W, H, 8, PNG_COLOR_TYPE_PALETTE, idx, 1));
    float *f = model_image_read(ppal, MODEL_CHANNEL_LUMA, &w, &h, NULL);
    CHECK(f != NULL);
    if (f) CHECK(f[0] == 0 && fabsf(f[1] - (float)(MODEL_LUMA_R * 255)) < 1e-3f);
    free(f);
    f = model_image_read(ppal, MODEL_CHANNEL_R, &w, &h, NULL);
    if (f) CHECK(f[0] == 0 && f[1] == 255);
    free(f);
}

// Colour PNG, 8- and 16-bit, with and without alpha: luma by the stated
// weights, or one channel.
TEST(image_png_colour_channels)
{
    enum { W = 5, H = 3 };
    uint8_t rgb8[W * H * 3], rgba16[W * H * 4 * 2];
    double want[W * H][3];
    for (int i = 0; i < W * H; i++) {
        int r = 10 + 17 * i, gg = 250 - 9 * i, b = (i * 53) % 256;
        rgb8[3 * i] = (uint8_t)r, rgb8[3 * i + 1] = (uint8_t)gg, rgb8[3 * i + 2] = (uint8_t)b;
        want[i][0] = r, want[i][1] = gg, want[i][2] = b;
        int v16[4] = { r * 257 + 3, gg * 250, b * 199, 1234 };   // the alpha is ignored
        for (int c = 0; c < 4; c++) {   // big-endian
            rgba16[2 * (4 * i + c)] = (uint8_t)(v16[c] >> 8);
            rgba16[2 * (4 * i + c) + 1] = (uint8_t)(v16[c] & 0xff);
        }
    }
    const char *p8 = test_path("c8.png"), *p16 = test_path("c16.png");
    CHECK(write_png_raw(p8, W, H, 8, PNG_COLOR_TYPE_RGB, rgb8, 3));
    CHECK(write_png_raw(p16, W, H, 16, PNG_COLOR_TYPE_RGBA, rgba16, 4));
    const model_channel_t chs[4] = { MODEL_CHANNEL_LUMA, MODEL_CHANNEL_R, MODEL_CHANNEL_G, MODEL_CHANNEL_B };
    for (int k = 0; k < 4; k++) {
        int w = 0, h = 0;
        float *a = model_image_read(p8, chs[k], &w, &h, NULL);
        CHECK(a != NULL && w == W && h == H);
        int w2 = 0, h2 = 0;
        float *b = model_image_read(p16, chs[k], &w2, &h2, NULL);
        CHECK(b != NULL && w2 == W && h2 == H);
        for (int i = 0; a && b && i < W * H; i++) {
            double v16[3] = { want[i][0] * 257 + 3, want[i][1] * 250, want[i][2] * 199 };
            double e8 = k ? want[i][k - 1] : 0.2126 * want[i][0] + 0.7152 * want[i][1] + 0.0722 * want[i][2];
            double e16 = k ? v16[k - 1] : 0.2126 * v16[0] + 0.7152 * v16[1] + 0.0722 * v16[2];
            CHECK_NEAR(a[i], e8, 1e-4 * (1 + e8));
            CHECK_NEAR(b[i], e16, 1e-6 * (1 + e16));
        }
        free(a);
        free(b);
    }
    // grey + alpha: the grey values, the alpha ignored
    uint8_t ga[W * H * 2];
    for (int i = 0; i < W * H; i++) ga[2 * i] = (uint8_t)(i * 11), ga[2 * i + 1] = (uint8_t)(255 - i);
    const char *pga = test_path("ga.png");
    CHECK(write_png_raw(pga, W, H, 8, PNG_COLOR_TYPE_GRAY_ALPHA, ga, 2));
    for (int k = 0; k < 4; k++) {
        int w = 0, h = 0;
        float *a = model_image_read(pga, chs[k], &w, &h, NULL);
        CHECK(a != NULL && w == W && h == H);
        for (int i = 0; a && i < W * H; i++) CHECK(a[i] == (float)(uint8_t)(i * 11));
        free(a);
    }
    // the process-wide channel of the path-only readers, as --channel sets it
    model_image_set_channel(MODEL_CHANNEL_G);
    int w, h;
    float *g = model_image_read_float(p8, &w, &h);
    model_image_set_channel(MODEL_CHANNEL_LUMA);
    CHECK(g != NULL);
    if (g) CHECK(g[2] == (float)want[2][1]);
    free(g);
    model_channel_t ch;
    CHECK(model_channel_parse("b", &ch) && ch == MODEL_CHANNEL_B);
    CHECK(!model_channel_parse("red", &ch));
}

TEST(image_png_errors)
{
    enum { W = 64, H = 48 };
    uint16_t pix[W * H];
    for (int i = 0; i < W * H; i++) pix[i] = (uint16_t)(i * 31 + (i % 7) * 1000);
    const char *good = test_path("good.png");
    CHECK(model_png16_write(good, W, H, pix, NULL));
    int w, h;
    uint16_t *back = NULL;

    const char *trunc = test_path("trunc.png");
    truncate_copy(good, trunc, 0.5, -1);
    CHECK(!model_png_read(trunc, &w, &h, &back));
    CHECK(back == NULL);
    CHECK_CONTAINS(model_last_error(), trunc);
    CHECK_CONTAINS(model_last_error(), "corrupt or truncated PNG");

    const char *text = test_write("text.png", "just some text, not an image\n");
    CHECK(!model_png_read(text, &w, &h, &back));
    CHECK_CONTAINS(model_last_error(), text);
    CHECK_CONTAINS(model_last_error(), "not an image refl reads");

    const char *missing = test_path("missing.png");
    CHECK(!model_png_read(missing, &w, &h, &back));
    CHECK_CONTAINS(model_last_error(), missing);
    CHECK_CONTAINS(model_last_error(), "cannot open");

    // every truncation length and flipped bytes: an image or an error naming
    // the file, never a crash
    size_t len;
    char *buf = model_read_file(good, &len);
    CHECK(buf != NULL);
    free(buf);
    const char *bad = test_path("bad.png");
    int nerr = 0, nok = 0;
    for (size_t cut = 0; cut < len; cut += 7) {
        truncate_copy(good, bad, (double)cut / len, -1);
        if (model_png_read(bad, &w, &h, &back)) {
            nok++;
            free(back);
            back = NULL;
        } else {
            nerr++;
            CHECK_CONTAINS(model_last_error(), bad);
        }
    }
    CHECK(nok == 0 && nerr > 0);
    for (long at = 8; at < (long)len; at += 5) {
        truncate_copy(good, bad, 1.0, at);
        if (model_png_read(bad, &w, &h, &back)) {
            free(back);
            back = NULL;
        } else {
            CHECK_CONTAINS(model_last_error(), bad);
        }
    }

    // a header that claims 16000 x 16000 pixels in a file of 57 bytes: refused before any allocation
    unsigned char hdr[57] = { 0x89, 'P', 'N', 'G', '\r', '\n', 0x1a, '\n', 0, 0, 0, 13, 'I', 'H', 'D', 'R',
                              0, 0, 0x3e, 0x80, 0, 0, 0x3e, 0x80, 8, 0, 0, 0, 0 };
    uLong crc = crc32(0, hdr + 12, 17);
    for (int i = 0; i < 4; i++) hdr[29 + i] = (unsigned char)(crc >> (24 - 8 * i));
    memcpy(hdr + 33, "\0\0\0\0IDAT\x35\xaf\x06\x1e\0\0\0\0IEND\xae\x42\x60\x82", 24);
    const char *huge = test_path("huge.png");
    CHECK(g_file_set_contents(huge, (const char *)hdr, sizeof hdr, NULL));
    CHECK(!model_png_read(huge, &w, &h, &back));
    CHECK_CONTAINS(model_last_error(), "a PNG of 16000x16000 pixels cannot fit in its 57 bytes");

    // writing: a bad metadata key, and an impossible path
    const char *meta[] = { "", "x", NULL };
    CHECK(!model_png16_write(test_path("m.png"), W, H, pix, meta));
    CHECK_CONTAINS(model_last_error(), "metadata key ''");
    CHECK(!model_png16_write("/nonexistent-dir/x.png", W, H, pix, NULL));
    CHECK_CONTAINS(model_last_error(), "/nonexistent-dir/x.png");
}

TEST(image_tiff_float_round_trip)
{
    enum { W = 123, H = 77 };
    float *pix = malloc(W * H * sizeof *pix);
    for (int i = 0; i < W * H; i++) pix[i] = (float)(sin(i * 0.37) * 1000.0 + i * 1e-3);
    pix[0] = -0.0f;
    pix[1] = 1e-40f;   // subnormal
    pix[2] = 3.4e38f;
    pix[3] = INFINITY;
    const char *meta[] = { "kc", "1.25", "camera", "cam0.cameramodel", NULL };
    const char *path = test_path("f.tif");
    CHECK(model_tiff_write_float(path, W, H, pix, meta));
    int w, h;
    float *back = NULL;
    CHECK(model_tiff_read_float(path, &w, &h, &back));
    CHECK(w == W && h == H);
    if (back) CHECK(memcmp(pix, back, W * H * sizeof *pix) == 0);   // bit for bit
    free(back);
    TIFF *t = test_tiff_open(path);
    CHECK(t != NULL);
    if (t) {
        char *desc = NULL;
        uint16_t bps = 0, fmt = 0;
        CHECK(TIFFGetField(t, TIFFTAG_IMAGEDESCRIPTION, &desc) == 1);
        if (desc) CHECK(strcmp(desc, "kc: 1.25\ncamera: cam0.cameramodel\n") == 0);
        TIFFGetField(t, TIFFTAG_BITSPERSAMPLE, &bps);
        TIFFGetField(t, TIFFTAG_SAMPLEFORMAT, &fmt);
        CHECK(bps == 32 && fmt == SAMPLEFORMAT_IEEEFP);
        TIFFClose(t);
    }
    const char *bad[] = { "a:b", "x", NULL };
    CHECK(!model_tiff_write_float(test_path("g.tif"), W, H, pix, bad));
    CHECK_CONTAINS(model_last_error(), "metadata key 'a:b'");
    const char *bad2[] = { "k", "two\nlines", NULL };
    CHECK(!model_tiff_write_float(test_path("g.tif"), W, H, pix, bad2));
    CHECK_CONTAINS(model_last_error(), "line break");
    free(pix);
}

TEST(image_tiff_info_pages)
{
    enum { W = 40, H = 30, NL = 3 };
    float P[W * H];
    int32_t face[W * H];
    uint8_t lit[NL * W * H];
    for (int i = 0; i < W * H; i++) {
        P[i] = (float)(i * 0.5);
        face[i] = i % 5 == 0 ? -1 : i % 17;
        for (int l = 0; l < NL; l++) lit[l * W * H + i] = (uint8_t)((i + l) % 3 == 0);
    }
    const char *names[NL] = { "left", "right", "top" };
    const char *meta[] = { "scene", "t_stiffener.d3d", NULL };
    const char *path = test_path("info.tif");
    CHECK(model_tiff_write_info(path, W, H, P, face, lit, NL, names, meta));
    TIFF *t = test_tiff_open(path);
    CHECK(t != NULL);
    if (!t) return;
    int pages = 0;
    do {
        char *name = NULL;
        uint16_t bps = 0, fmt = 0;
        uint32_t w = 0, h = 0;
        CHECK(TIFFGetField(t, TIFFTAG_PAGENAME, &name) == 1);
        TIFFGetField(t, TIFFTAG_BITSPERSAMPLE, &bps);
        TIFFGetFieldDefaulted(t, TIFFTAG_SAMPLEFORMAT, &fmt);
        TIFFGetField(t, TIFFTAG_IMAGEWIDTH, &w);
        TIFFGetField(t, TIFFTAG_IMAGELENGTH, &h);
        CHECK(w == W && h == H);
        unsigned char row[W * 4];
        bool same = true;
        if (pages == 0) {
            CHECK(name && strcmp(name, "P") == 0);
            CHECK(bps == 32 && fmt == SAMPLEFORMAT_IEEEFP);
            char *desc = NULL;
            CHECK(TIFFGetField(t, TIFFTAG_IMAGEDESCRIPTION, &desc) == 1);
            if (desc) CHECK(strcmp(desc, "scene: t_stiffener.d3d\n") == 0);
            for (int y = 0; y < H; y++)
                same = same && TIFFReadScanline(t, row, y, 0) == 1 && memcmp(row, P + y * W, W * 4) == 0;
        } else if (pages == 1) {
            CHECK(name && strcmp(name, "face") == 0);
            CHECK(bps == 32 && fmt == SAMPLEFORMAT_INT);
            for (int y = 0; y < H; y++)
                same = same && TIFFReadScanline(t, row, y, 0) == 1 && memcmp(row, face + y * W, W * 4) == 0;
        } else {
            char expect[32];
            snprintf(expect, sizeof expect, "lit %s", pages - 2 < NL ? names[pages - 2] : "?");
            CHECK(name && strcmp(name, expect) == 0);
            CHECK(bps == 8 && fmt == SAMPLEFORMAT_UINT);
            for (int y = 0; y < H && pages - 2 < NL; y++)
                same = same && TIFFReadScanline(t, row, y, 0) == 1 &&
                       memcmp(row, lit + (pages - 2) * W * H + y * W, W) == 0;
        }
        CHECK_MSG(same, "page %d data differs", pages);
        pages++;
    } while (TIFFReadDirectory(t));
    TIFFClose(t);
    CHECK(pages == 2 + NL);
    // the first page reads as a float image
    int w, h;
    float *back = NULL;
    CHECK(model_tiff_read_float(path, &w, &h, &back));
    if (back) CHECK(memcmp(back, P, sizeof P) == 0);
    free(back);
    // no lamps: two pages
    CHECK(model_tiff_write_info(test_path("info0.tif"), W, H, P, face, NULL, 0, NULL, NULL));
}

// 16- and 8-bit integer TIFFs read as float
TEST(image_tiff_integer_read)
{
    enum { W = 50, H = 20 };
    for (int bits = 8; bits <= 16; bits += 8) {
        const char *path = test_path(bits == 8 ? "u8.tif" : "u16.tif");
        TIFF *t = TIFFOpen(path, "w");
        CHECK(t != NULL);
        if (!t) continue;
        TIFFSetField(t, TIFFTAG_IMAGEWIDTH, W);
        TIFFSetField(t, TIFFTAG_IMAGELENGTH, H);
        TIFFSetField(t, TIFFTAG_BITSPERSAMPLE, bits);
        TIFFSetField(t, TIFFTAG_SAMPLESPERPIXEL, 1);
        TIFFSetField(t, TIFFTAG_PHOTOMETRIC, PHOTOMETRIC_MINISBLACK);
        TIFFSetField(t, TIFFTAG_ROWSPERSTRIP, 7);
        uint16_t row16[W];
        uint8_t row8[W];
        for (int y = 0; y < H; y++) {
            for (int x = 0; x < W; x++) {
                row16[x] = (uint16_t)(y * 3000 + x * 7);
                row8[x] = (uint8_t)(y * 11 + x);
            }
            TIFFWriteScanline(t, bits == 8 ? (void *)row8 : (void *)row16, y, 0);
        }
        TIFFClose(t);
        int w, h;
        float *back = NULL;
        CHECK(model_tiff_read_float(path, &w, &h, &back));
        CHECK(w == W && h == H);
        if (back) {
            bool same = true;
            for (int y = 0; y < H; y++)
                for (int x = 0; x < W; x++)
                    same = same && back[y * W + x] == (bits == 8 ? (float)(uint8_t)(y * 11 + x)
                                                                 : (float)(y * 3000 + x * 7));
            CHECK(same);
        }
        free(back);
    }
}

TEST(image_tiff_errors)
{
    enum { W = 200, H = 100 };
    float *pix = malloc(W * H * sizeof *pix);
    for (int i = 0; i < W * H; i++) pix[i] = (float)i;
    const char *good = test_path("good.tif");
    CHECK(model_tiff_write_float(good, W, H, pix, NULL));
    free(pix);
    int w, h;
    float *back = NULL;

    const char *trunc = test_path("trunc.tif");
    truncate_copy(good, trunc, 0.5, -1);
    CHECK(!model_tiff_read_float(trunc, &w, &h, &back));
    CHECK(back == NULL);
    CHECK_CONTAINS(model_last_error(), trunc);

    const char *text = test_write("text.tif", "not a TIFF at all\n");
    CHECK(!model_tiff_read_float(text, &w, &h, &back));
    CHECK_CONTAINS(model_last_error(), text);
    CHECK_CONTAINS(model_last_error(), "not an image refl reads");

    const char *missing = test_path("missing.tif");
    CHECK(!model_tiff_read_float(missing, &w, &h, &back));
    CHECK_CONTAINS(model_last_error(), missing);
    CHECK_CONTAINS(model_last_error(), "cannot open");

    // truncations and flipped bytes: an image or an error naming the file
    size_t len;
    char *buf = model_read_file(good, &len);
    CHECK(buf != NULL);
    free(buf);
    const char *bad = test_path("bad.tif");
    for (size_t cut = 0; cut < len; cut += len / 97 + 1) {
        truncate_copy(good, bad, (double)cut / len, -1);
        if (model_tiff_read_float(bad, &w, &h, &back)) {
            free(back);
            back = NULL;
        } else {
            CHECK_CONTAINS(model_last_error(), bad);
        }
    }
    for (long at = 0; at < (long)len; at += (long)(len / 211) + 1) {
        truncate_copy(good, bad, 1.0, at);
        if (model_tiff_read_float(bad, &w, &h, &back)) {
            free(back);
            back = NULL;
        } else {
            CHECK_CONTAINS(model_last_error(), bad);
        }
    }
    CHECK(!model_tiff_write_float("/nonexistent-dir/x.tif", W, H, (const float[W * H]){ 0 }, NULL));
    CHECK_CONTAINS(model_last_error(), "/nonexistent-dir/x.tif");
}

// A JPEG written with libjpeg: nch 1 (grey) or 3 (RGB), quality 100.
static bool write_jpeg(const char *path, int w, int h, int nch, const uint8_t *pix)
{
    FILE *f = fopen(path, "wb");
    if (!f) return false;
    struct jpeg_compress_struct c;
    struct jpeg_error_mgr e;
    c.err = jpeg_std_error(&e);
    jpeg_create_compress(&c);
    jpeg_stdio_dest(&c, f);
    c.image_width = (JDIMENSION)w;
    c.image_height = (JDIMENSION)h;
    c.input_components = nch;
    c.in_color_space = nch == 1 ? JCS_GRAYSCALE : JCS_RGB;
    jpeg_set_defaults(&c);
    jpeg_set_quality(&c, 100, TRUE);
    if (nch == 3) {   // no chroma subsampling: flat colour blocks stay exact to a DN or two
        for (int i = 0; i < 3; i++) c.comp_info[i].h_samp_factor = c.comp_info[i].v_samp_factor = 1;
    }
    jpeg_start_compress(&c, TRUE);
    while (c.next_scanline < c.image_height) {
        JSAMPROW r = (JSAMPROW)(pix + (size_t)c.next_scanline * w * nch);
        jpeg_write_scanlines(&c, &r, 1);
    }
    jpeg_finish_compress(&c);
    jpeg_destroy_compress(&c);
    return fclose(f) == 0;
}

// JPEG, told by content (the grey one is named .png): grey values and a colour
// image's channels and luma within JPEG's rounding; truncated: a clear error.
TEST(image_jpeg_grey_and_colour)
{
    enum { W = 32, H = 16 };
    uint8_t grey[W * H], rgb[W * H * 3];
    for (int y = 0; y < H; y++)
        for (int x = 0; x < W; x++) {
            bool left = x < W / 2;   // two flat 16x16 blocks (whole 8x8 JPEG blocks)
            grey[y * W + x] = left ? 40 : 200;
            uint8_t *p = rgb + 3 * (y * W + x);
            p[0] = left ? 200 : 30, p[1] = left ? 60 : 120, p[2] = left ? 20 : 220;
        }
    const char *pg = test_path("grey_jpeg.png"), *pc = test_path("colour.jpg");
    CHECK(write_jpeg(pg, W, H, 1, grey));
    CHECK(write_jpeg(pc, W, H, 3, rgb));
    int w = 0, h = 0;
    float *g = model_image_read_float(pg, &w, &h);
    CHECK(g != NULL && w == W && h == H);
    for (int i = 0; g && i < W * H; i += 7) CHECK_NEAR(g[i], grey[i], 1.01);
    free(g);
    for (int k = 0; k < 4; k++) {
        float *c = model_image_read(pc, (model_channel_t)k, &w, &h, NULL);
        CHECK(c != NULL && w == W && h == H);
        for (int i = 0; c && i < W * H; i += 5) {
            const uint8_t *p = rgb + 3 * i;
            double e = k ? p[k - 1] : MODEL_LUMA_R * p[0] + MODEL_LUMA_G * p[1] + MODEL_LUMA_B * p[2];
            CHECK_NEAR(c[i], e, 2.01);
        }
        free(c);
    }
    CHECK(model_image_format("\xff\xd8\xff\xe0", 4) == MODEL_IMAGE_JPEG);

    const char *trunc = test_path("trunc.jpg");
    truncate_copy(pc, trunc, 0.6, -1);
    CHECK(model_image_read_float(trunc, &w, &h) == NULL);
    CHECK_CONTAINS(model_last_error(), trunc);
    CHECK_CONTAINS(model_last_error(), "corrupt or truncated JPEG");
    // every cut and flipped bytes: an image or an error naming the file
    size_t len;
    char *buf = model_read_file(pc, &len);
    CHECK(buf != NULL);
    free(buf);
    const char *bad = test_path("bad.jpg");
    for (size_t cut = 0; cut < len; cut += len / 61 + 1) {
        truncate_copy(pc, bad, (double)cut / len, -1);
        float *r = model_image_read_float(bad, &w, &h);
        if (!r) CHECK_CONTAINS(model_last_error(), bad);
        free(r);
    }
    for (long at = 0; at < (long)len; at += (long)(len / 97) + 1) {
        truncate_copy(pc, bad, 1.0, at);
        float *r = model_image_read_float(bad, &w, &h);
        if (!r) CHECK_CONTAINS(model_last_error(), bad);
        free(r);
    }
}

// An RGB TIFF written with libtiff: 16-bit contiguous, 16-bit planar, float.
// spp: 3 (RGB), or 2 (grey and alpha: v holds w*h*2 values).
static bool write_tiff_spp(const char *path, int w, int h, int bits, bool planar, const double *v, int spp)
{
    TIFFSetWarningHandler(NULL);
    TIFF *t = TIFFOpen(path, "w");
    if (!t) return false;
    TIFFSetField(t, TIFFTAG_IMAGEWIDTH, (uint32_t)w);
    TIFFSetField(t, TIFFTAG_IMAGELENGTH, (uint32_t)h);
    TIFFSetField(t, TIFFTAG_BITSPERSAMPLE, bits);
    TIFFSetField(t, TIFFTAG_SAMPLESPERPIXEL, spp);
    TIFFSetField(t, TIFFTAG_SAMPLEFORMAT, bits == 32 ? SAMPLEFORMAT_IEEEFP : SAMPLEFORMAT_UINT);
    TIFFSetField(t, TIFFTAG_PHOTOMETRIC, spp == 3 ? PHOTOMETRIC_RGB : PHOTOMETRIC_MINISBLACK);
    if (spp == 2) {
        uint16_t extra = EXTRASAMPLE_UNASSALPHA;
        TIFFSetField(t, TIFFTAG_EXTRASAMPLES, 1, &extra);
    }
    TIFFSetField(t, TIFFTAG_PLANARCONFIG, planar ? PLANARCONFIG_SEPARATE : PLANARCONFIG_CONTIG);
    TIFFSetField(t, TIFFTAG_COMPRESSION, COMPRESSION_LZW);
    TIFFSetField(t, TIFFTAG_ROWSPERSTRIP, 2);
    size_t bps = (size_t)bits / 8;
    unsigned char *row = malloc((size_t)w * spp * bps);
    bool ok = row != NULL;
    for (int s = 0; ok && s < (planar ? spp : 1); s++)
        for (int y = 0; ok && y < h; y++) {
            for (int x = 0; x < w; x++)
                for (int c = 0; c < spp; c++) {
                    if (planar && c != s) continue;
                    double d = v[spp * (y * w + x) + c];
                    size_t at = planar ? (size_t)x : (size_t)x * spp + c;
                    if (bits == 32) { float f = (float)d; memcpy(row + at * 4, &f, 4); }
                    else { uint16_t u = (uint16_t)d; memcpy(row + at * 2, &u, 2); }
                }
            ok = TIFFWriteScanline(t, row, (uint32_t)y, (uint16_t)s) == 1;
        }
    free(row);
    TIFFClose(t);
    return ok;
}

static bool write_tiff_rgb(const char *path, int w, int h, int bits, bool planar, const double *v /* w*h*3 */)
{
    return write_tiff_spp(path, w, h, bits, planar, v, 3);
}

TEST(image_tiff_colour_16bit_and_float)
{
    enum { W = 9, H = 5 };
    double v[W * H * 3], vf[W * H * 3];
    for (int i = 0; i < W * H; i++)
        for (int c = 0; c < 3; c++) {
            v[3 * i + c] = (i * 1499 + c * 20011) % 65536;
            vf[3 * i + c] = 0.001 * i - 0.5 * c + 1e-7 * (i * c);
        }
    struct { const char *name; int bits; bool planar; const double *v; } cases[] = {
        { "rgb16.tif", 16, false, v }, { "rgb16p.tif", 16, true, v }, { "rgbf.tif", 32, false, vf },
        { "rgbfp.tif", 32, true, vf },
    };
    for (size_t k = 0; k < sizeof cases / sizeof cases[0]; k++) {
        const char *p = test_path(cases[k].name);
        CHECK_MSG(write_tiff_rgb(p, W, H, cases[k].bits, cases[k].planar, cases[k].v), "%s", p);
        for (int ch = 0; ch < 4; ch++) {
            int w = 0, h = 0;
            float *r = model_image_read(p, (model_channel_t)ch, &w, &h, NULL);
            CHECK_MSG(r != NULL && w == W && h == H, "%s: %s", p, model_last_error());
            for (int i = 0; r && i < W * H; i++) {
                double px[3];
                for (int c = 0; c < 3; c++) px[c] = cases[k].bits == 32 ? (float)cases[k].v[3 * i + c] : cases[k].v[3 * i + c];
                double e = ch ? px[ch - 1] : 0.2126 * px[0] + 0.7152 * px[1] + 0.0722 * px[2];
                CHECK_NEAR(r[i], e, 1e-6 * (1 + fabs(e)));
            }
            free(r);
        }
    }
    // grey and alpha, planar and contiguous: the grey values, whatever the channel
    double ga[W * H * 2];
    for (int i = 0; i < W * H; i++) ga[2 * i] = 100 + 37 * i, ga[2 * i + 1] = 65535 - i;
    for (int planar = 0; planar < 2; planar++) {
        const char *p = test_path(planar ? "gap.tif" : "ga.tif");
        CHECK(write_tiff_spp(p, W, H, 16, planar, ga, 2));
        for (int ch = 0; ch < 4; ch++) {
            int w = 0, h = 0;
            float *r = model_image_read(p, (model_channel_t)ch, &w, &h, NULL);
            CHECK_MSG(r != NULL && w == W && h == H, "%s: %s", p, model_last_error());
            for (int i = 0; r && i < W * H; i++) CHECK(r[i] == (float)(100 + 37 * i));
            free(r);
        }
    }
}

// An --images directory: the listing (sorted, regular files, no hidden ones),
// and each file read or refused with its reason.
TEST(image_list_directory_and_glob)
{
    const char *dir = test_path("imgs");
    CHECK(g_mkdir_with_parents(dir, 0755) == 0);
    char *good = g_build_filename(dir, "b_good.png", NULL), *txt = g_build_filename(dir, "a_notes.txt", NULL);
    char *corrupt = g_build_filename(dir, "c_corrupt.png", NULL), *hidden = g_build_filename(dir, ".hidden", NULL);
    char *sub = g_build_filename(dir, "subdir", NULL);
    uint16_t pix[64];
    for (int i = 0; i < 64; i++) pix[i] = (uint16_t)(i * 1000);
    CHECK(model_png16_write(good, 8, 8, pix, NULL));
    CHECK(g_file_set_contents(txt, "not an image\n", -1, NULL));
    CHECK(g_file_set_contents(hidden, "x", -1, NULL));
    truncate_copy(good, corrupt, 0.7, -1);
    CHECK(g_mkdir_with_parents(sub, 0755) == 0);
    char **paths = NULL;
    int n = 0;
    CHECK(model_image_list(dir, &paths, &n));
    CHECK(n == 3);
    if (n == 3) {
        CHECK(!strcmp(paths[0], txt) && !strcmp(paths[1], good) && !strcmp(paths[2], corrupt));
        int w, h;
        float *f = model_image_read_float(paths[0], &w, &h);
        CHECK(f == NULL);
        CHECK_CONTAINS(model_last_error(), "not an image refl reads");
        f = model_image_read_float(paths[1], &w, &h);
        CHECK(f != NULL && w == 8 && f[63] == 63000);
        free(f);
        f = model_image_read_float(paths[2], &w, &h);
        CHECK(f == NULL);
        CHECK_CONTAINS(model_last_error(), "corrupt or truncated PNG");
    }
    model_image_list_free(paths, n);
    char *pat = g_build_filename(dir, "*.png", NULL);
    CHECK(model_image_list(pat, &paths, &n));
    CHECK(n == 2);
    model_image_list_free(paths, n);
    char *none = g_build_filename(dir, "*.jpg", NULL);
    CHECK(!model_image_list(none, &paths, &n));
    CHECK_CONTAINS(model_last_error(), "matches no file");
    CHECK(!model_image_list(sub, &paths, &n));
    CHECK_CONTAINS(model_last_error(), "holds no files");
    g_free(none);
    g_free(pat);
    g_free(good);
    g_free(txt);
    g_free(corrupt);
    g_free(hidden);
    g_free(sub);
}

// refl calib geometry --images DIR: the text file and the corrupt PNG are
// skipped with their reasons; with no image left the run is an error.
TEST(image_geometry_images_skips_with_reasons)
{
    const char *dir = test_path("geo_in");
    CHECK(g_mkdir_with_parents(dir, 0755) == 0);
    char *txt = g_build_filename(dir, "readme.txt", NULL), *corrupt = g_build_filename(dir, "broken.png", NULL);
    char *good = g_build_filename(dir, "blank.png", NULL);
    uint16_t pix[64 * 48];
    for (int i = 0; i < 64 * 48; i++) pix[i] = (uint16_t)(100 + i % 5);
    CHECK(model_png16_write(good, 64, 48, pix, NULL));
    truncate_copy(good, corrupt, 0.5, -1);
    CHECK(g_file_set_contents(txt, "notes\n", -1, NULL));
    unlink(good);
    char *out = NULL, *err = NULL;
    int rc = test_refl_run(60, &out, &err, "calib", "geometry", "--images", dir, "-o", test_path("geo_out0"), NULL);
    CHECK(rc == 1);
    CHECK_CONTAINS(err, "skipped ");
    CHECK_CONTAINS(err, "readme.txt: not an image refl reads");
    CHECK_CONTAINS(err, "broken.png: corrupt or truncated PNG");
    CHECK_CONTAINS(err, "none of its 2 files is an image");
    free(out);
    free(err);
    // a bad --channel is a usage error
    rc = test_refl_run(30, &out, &err, "calib", "geometry", "--images", dir, "--channel", "red", "-o",
                       test_path("geo_out1"), NULL);
    CHECK(rc == 2);
    CHECK_CONTAINS(err, "--channel");
    free(out);
    free(err);
    g_free(txt);
    g_free(corrupt);
    g_free(good);
}

// A chessboard of 10 x 10 inner corners drawn in the green channel only (red
// and blue flat), as colour JPEG, PNG and 16-bit TIFF in one directory with a
// text file: refl calib geometry --images DIR finds the board in all three
// (luma), in none with --channel r.
TEST(image_geometry_colour_boards_and_channel)
{
    enum { W = 640, H = 480, SQ = 30 };
    uint8_t *rgb = malloc((size_t)W * H * 3);
    for (int y = 0; y < H; y++)
        for (int x = 0; x < W; x++) {
            int bx = (x - 150) / SQ, by = (y - 70) / SQ;
            bool on = x >= 150 && y >= 70 && bx < 11 && by < 11;
            bool dark = on && (bx + by) % 2 == 0;
            uint8_t *p = rgb + 3 * ((size_t)y * W + x);
            p[0] = 200, p[1] = dark ? 20 : 235, p[2] = 120;
        }
    const char *dir = test_path("boards");
    CHECK(g_mkdir_with_parents(dir, 0755) == 0);
    char *pj = g_build_filename(dir, "board_a.jpg", NULL), *pp = g_build_filename(dir, "board_b.png", NULL);
    char *pt = g_build_filename(dir, "board_c.tif", NULL), *px = g_build_filename(dir, "notes.txt", NULL);
    CHECK(write_jpeg(pj, W, H, 3, rgb));
    CHECK(write_png_raw(pp, W, H, 8, PNG_COLOR_TYPE_RGB, rgb, 3));
    double *v = malloc((size_t)W * H * 3 * sizeof *v);
    for (size_t i = 0; i < (size_t)W * H * 3; i++) v[i] = rgb[i] * 257.0;
    CHECK(write_tiff_rgb(pt, W, H, 16, false, v));
    CHECK(g_file_set_contents(px, "calibration notes\n", -1, NULL));
    free(v);
    free(rgb);
    char *out = NULL, *err = NULL;
    int rc = test_refl_run(120, &out, &err, "calib", "geometry", "--images", dir, "-o", test_path("geo_col"), NULL);
    CHECK(rc == 1);   // three views are too few for a solve
    CHECK_CONTAINS(err, "skipped ");
    CHECK_CONTAINS(err, "notes.txt: not an image refl reads");
    CHECK_CONTAINS(err, "the board was found in 3 of 3 images");
    free(out);
    free(err);
    rc = test_refl_run(120, &out, &err, "calib", "geometry", "--images", dir, "--channel", "r", "-o",
                       test_path("geo_col_r"), NULL);
    CHECK(rc == 1);
    CHECK_CONTAINS(err, "board_a.jpg): mrgingham found no 10x10 board");
    CHECK_CONTAINS(err, "the board was found in 0 of 3 images");
    free(out);
    free(err);
    g_free(pj);
    g_free(pp);
    g_free(pt);
    g_free(px);
}
