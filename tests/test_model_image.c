// tests/test_model_image.c — image files: PNG and TIFF round trips with metadata,
// the multi-page info TIFF, other sample types, and clean errors on damaged
// files.
#define _GNU_SOURCE
#include <png.h>
#include <stdlib.h>
#include <tiffio.h>

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
        for (int y = 0; y < h; y++) png_write_row(png, (png_const_bytep)(data + (size_t)y * w * channels));
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

    const char *prgb = test_path("rgb.png");
    CHECK(write_png_raw(prgb, W, H, 8, PNG_COLOR_TYPE_RGB, rgb, 3));
    back = NULL;
    CHECK(!model_png_read(prgb, &w, &h, &back));
    CHECK(back == NULL);
    CHECK_CONTAINS(model_last_error(), prgb);
    CHECK_CONTAINS(model_last_error(), "colour (RGB) PNG");

    const char *ppal = test_path("pal.png");
    CHECK(write_png_raw(ppal, W, H, 8, PNG_COLOR_TYPE_PALETTE, idx, 1));
    CHECK(!model_png_read(ppal, &w, &h, &back));
    CHECK_CONTAINS(model_last_error(), ppal);
    CHECK_CONTAINS(model_last_error(), "palette");
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
    CHECK_CONTAINS(model_last_error(), "not a PNG file");

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
    CHECK_CONTAINS(model_last_error(), "not a readable TIFF");

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
