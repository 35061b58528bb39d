// tests/test_calib_boards.c — boards other than mrgingham's square
// chessboard (issue 20, item 2): W x H chessboards and ChArUco boards.
//
// - The detector (calib/board_detect.h, OpenCV) on synthetic images with known
//   corners: a board rendered through a homography (calib_board_render, 8 x 8
//   samples a pixel, a little blur and noise), every corner found checked
//   against its true position (sub-pixel: stated tolerance below); a ChArUco
//   board partly out of the image gives the corners it shows, with their ids;
//   a blank image no board, with the reason; bad board descriptions refused.
// - mrcal with missing corners: synthetic corners of an 8 x 6 board projected
//   through the example camera, some views cut by the imager's edge (their
//   corners beyond it written "- -" as mrcal reads them), solved through
//   --corners: the partial views are used, a view of too few corners is left
//   out with the reason, the projection agrees with the truth's.
// - The virtual rig: an 8 x 6 chessboard (scripts/make-calib-board 8x6) and a
//   ChArUco board (scripts/make-charuco-board), generated into the test's
//   directory with a copy of examples/virtual-truth.ini that names them,
//   rendered, found by OpenCV and calibrated through `refl calib geometry
//   --rig`, against the truth camera as calib_geometry_virtual_rig judges it
//   (the mrcal-style projection difference at 900 mm over the imager).
// - Usage errors of the board options.
#define _GNU_SOURCE
#include <glib.h>
#include <jansson.h>
#include <limits.h>
#include <mrcal/mrcal.h>
#include <mrcal/poseutils.h>
#include <stdlib.h>
#include <unistd.h>

#include "calib/board_detect.h"
#include "calib/geometry.h"
#include "model/model.h"
#include "tests/fixtures.h"
#include "tests/test.h"

#define DEG (M_PI / 180.0)

// Deterministic numbers (xorshift; Box-Muller).
static uint64_t rng = 0x9E3779B97F4A7C15ull;
static double urand(void)
{
    rng ^= rng << 13;
    rng ^= rng >> 7;
    rng ^= rng << 17;
    return (double)(rng >> 11) / 9007199254740992.0;
}
static double nrand(void)
{
    double u = urand(), v = urand();
    return sqrt(-2 * log(u > 1e-300 ? u : 1e-300)) * cos(2 * M_PI * v);
}

// H = K [r1 r2 t] of a board at pose rt (r rad, t mm) seen by a pinhole f, (cx, cy).
static void homography(const double rt[6], double f, double cx, double cy, double H[9])
{
    double R[9];
    mrcal_R_from_r(R, NULL, rt);
    const double cols[3][3] = { { R[0], R[3], R[6] }, { R[1], R[4], R[7] }, { rt[3], rt[4], rt[5] } };
    for (int c = 0; c < 3; c++) {
        H[0 * 3 + c] = f * cols[c][0] + cx * cols[c][2];
        H[1 * 3 + c] = f * cols[c][1] + cy * cols[c][2];
        H[2 * 3 + c] = cols[c][2];
    }
}

static void apply_h(const double H[9], double x, double y, double *u, double *v)
{
    double w = H[6] * x + H[7] * y + H[8];
    *u = (H[0] * x + H[1] * y + H[2]) / w;
    *v = (H[3] * x + H[4] * y + H[5]) / w;
}

// A 3 x 3 binomial blur (a lens's) and Gaussian noise of sigma grey levels.
static void blur_noise(unsigned char *img, int w, int h, double sigma)
{
    unsigned char *t = malloc((size_t)w * h);
    memcpy(t, img, (size_t)w * h);
    for (int y = 1; y < h - 1; y++)
        for (int x = 1; x < w - 1; x++) {
            double s = 0;
            for (int dy = -1; dy <= 1; dy++)
                for (int dx = -1; dx <= 1; dx++) s += t[(y + dy) * w + x + dx] * (2 - abs(dx)) * (2 - abs(dy));
            s = s / 16 + sigma * nrand();
            img[y * w + x] = s <= 0 ? 0 : s >= 255 ? 255 : (unsigned char)lround(s);
        }
    free(t);
}

// Every corner found against the truth (H of board point (i, j) spacing); the
// largest error, px; *bad: found corners more than 1 px off (a wrong id).
static double corner_errors(const calib_board_t *b, const double H[9], const double *q, int *nfound, int *bad,
                            double *rms)
{
    double worst = 0, ss = 0;
    *nfound = *bad = 0;
    for (int k = 0; k < b->width_n * b->height_n; k++) {
        if (!isfinite(q[2 * k])) continue;
        double u, v;
        apply_h(H, (k % b->width_n) * b->spacing_mm, (k / b->width_n) * b->spacing_mm, &u, &v);
        double e = hypot(q[2 * k] - u, q[2 * k + 1] - v);
        (*nfound)++;
        if (e > 1) (*bad)++;
        worst = fmax(worst, e);
        ss += e * e;
    }
    *rms = *nfound ? sqrt(ss / *nfound) : NAN;
    return worst;
}

// The chessboard's order is the detector's, up to a half turn (and made
// right-handed in the image): compare with the truth in both orders.
static void reverse(double *q, int n)
{
    for (int a = 0, z = n - 1; a < z; a++, z--)
        for (int c = 0; c < 2; c++) {
            double t = q[2 * a + c];
            q[2 * a + c] = q[2 * z + c];
            q[2 * z + c] = t;
        }
}

TEST(calib_boards_detect_synthetic)
{
    const int W = 800, H = 600;
    unsigned char *img = malloc((size_t)W * H);
    double q[2 * 48], Hm[9];
    char why[256];
    int n, nfound, bad;
    double rms;

    // an 8 x 6 chessboard, 30 mm squares, 700 mm away, tilted 25 deg
    calib_board_t cb = { .kind = CALIB_BOARD_CHESSBOARD, .width_n = 8, .height_n = 6, .spacing_mm = 30 };
    double rt[6] = { 25 * DEG, -10 * DEG, 8 * DEG, -100, -80, 700 };
    homography(rt, 1100, (W - 1) / 2.0, (H - 1) / 2.0, Hm);
    CHECK(calib_board_render(&cb, Hm, W, H, 8, img));
    blur_noise(img, W, H, 1.0);
    double t0 = model_realtime_s();
    n = calib_board_detect(&cb, img, W, H, q, why, sizeof why);
    double t_cb = model_realtime_s() - t0;
    CHECK_MSG(n == 48, "chessboard: %d corners (%s)", n, why);
    if (n == 48) {
        double worst = corner_errors(&cb, Hm, q, &nfound, &bad, &rms);
        if (bad) {   // the other of the two orders a half turn apart
            reverse(q, 48);
            worst = corner_errors(&cb, Hm, q, &nfound, &bad, &rms);
        }
        fprintf(stderr, "  8x6 chessboard (OpenCV findChessboardCornersSB, %.2f s): %d corners, error RMS %.4f px, "
                "worst %.4f px\n", t_cb, nfound, rms, worst);
        CHECK(bad == 0);
        CHECK(rms < 0.05);
        CHECK(worst < 0.12);
    }

    // a ChArUco board of 8 x 6 inner corners (9 x 7 squares), markers 22.5 mm, DICT_4X4_50
    calib_board_t ch = { .kind = CALIB_BOARD_CHARUCO, .width_n = 8, .height_n = 6, .spacing_mm = 30,
                         .marker_mm = 22.5, .dict = "DICT_4X4_50" };
    CHECK(calib_board_render(&ch, Hm, W, H, 8, img));
    blur_noise(img, W, H, 1.0);
    t0 = model_realtime_s();
    n = calib_board_detect(&ch, img, W, H, q, why, sizeof why);
    double t_ch = model_realtime_s() - t0;
    CHECK_MSG(n == 48, "charuco: %d corners (%s)", n, why);
    double worst = corner_errors(&ch, Hm, q, &nfound, &bad, &rms);
    fprintf(stderr, "  8x6 ChArUco (OpenCV aruco, %.2f s): %d corners, error RMS %.4f px, worst %.4f px\n", t_ch,
            nfound, rms, worst);
    CHECK(nfound == 48 && bad == 0);
    CHECK(rms < 0.05);
    CHECK(worst < 0.12);

    // the same board partly out of the image: the corners it shows, by their ids
    double rt2[6] = { 15 * DEG, 20 * DEG, -20 * DEG, 20, -60, 650 };
    homography(rt2, 1100, (W - 1) / 2.0, (H - 1) / 2.0, Hm);
    CHECK(calib_board_render(&ch, Hm, W, H, 8, img));
    blur_noise(img, W, H, 1.0);
    int inside = 0;
    for (int k = 0; k < 48; k++) {
        double u, v;
        apply_h(Hm, (k % 8) * 30.0, (k / 8) * 30.0, &u, &v);
        inside += u > 20 && u < W - 21 && v > 20 && v < H - 21;
    }
    n = calib_board_detect(&ch, img, W, H, q, why, sizeof why);
    worst = corner_errors(&ch, Hm, q, &nfound, &bad, &rms);
    fprintf(stderr, "  ChArUco partly out of the image: %d of 48 corners found (%d well inside), error RMS %.4f px, "
            "worst %.4f px\n", nfound, inside, rms, worst);
    CHECK(inside > 10 && inside < 40);
    CHECK(n == nfound && nfound >= inside - 8 && nfound < 48);
    CHECK(bad == 0);
    CHECK(rms < 0.05);
    CHECK(worst < 0.15);

    // no board: a blank image says so
    memset(img, 200, (size_t)W * H);
    n = calib_board_detect(&ch, img, W, H, q, why, sizeof why);
    CHECK(n == 0);
    CHECK_CONTAINS(why, "no ArUco marker of DICT_4X4_50");
    n = calib_board_detect(&cb, img, W, H, q, why, sizeof why);
    CHECK(n == 0);
    CHECK_CONTAINS(why, "no 8x6 chessboard");
    CHECK(!isfinite(q[0]));

    // bad descriptions: the dictionary too small, the marker larger than its square, an unknown dictionary
    calib_board_t big = ch;
    big.width_n = big.height_n = 10;
    CHECK(calib_board_detect(&big, img, W, H, q, why, sizeof why) == -1);
    CHECK_CONTAINS(model_last_error(), "needs 60");
    CHECK(calib_board_dict_size("DICT_4X4_250") == 250 && calib_board_dict_size("DICT_5X5_1") == 0);
    calib_board_t fat = ch;
    fat.marker_mm = 31;
    CHECK(!calib_board_check(&fat));
    CHECK_CONTAINS(model_last_error(), "--charuco-marker-mm");
    free(img);
}
