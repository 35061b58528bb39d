// tests/test_calib_boards_photo.c — W x H chessboards in photographed-looking
// images: OpenCV's detectors in turn (calib/geometry/board_detect.h) against
// the known corners.
//
// An 8 x 6 chessboard (25 mm squares) printed on paper (black 30, white 234
// grey levels, a white margin of half a square) on a textured table, rendered
// through a known homography (calib_board_render, 3 x 3 samples a pixel) at a
// random pose (tilted, turned in the image, the paper inside the image), then
// degraded as a low-cost camera's photo would be (tests/photo_degrade.h,
// OpenCV), 8 views each: JPEG quality 60..90 (cv::imencode), uneven light (a
// gradient down to 25 % and a vignette), Gaussian blur 1.5..2.5 px,
// perspective 45..60 deg, barrel distortion, noise, small squares, paper not
// flat, glare, a narrow margin in dim light, a 320 x 240 camera, and all of
// them at once. Each view through the chain and through each detector alone.
// Asserted: the chain finds the board in >= 95 % of the views; every corner
// against its true position (RMS and worst per detector, bounds below); the
// single detector (findChessboardCornersSB alone) misses views the chain
// finds, each such view's attempts saying so; who found each view recorded.
#define _GNU_SOURCE
#include <math.h>
#include <mrcal/poseutils.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "calib/geometry/board_detect.h"
#include "model/model.h"
#include "tests/photo_degrade.h"
#include "tests/test.h"

#define DEG (M_PI / 180.0)
#define BW 8
#define BH 6
#define SQ 25.0

static uint64_t rng = 0x2545F4914F6CDD1Dull;
static double urand(void)
{
    rng ^= rng << 13;
    rng ^= rng >> 7;
    rng ^= rng << 17;
    return (double)(rng >> 11) / 9007199254740992.0;
}
static double uni(double a, double b)
{
    return a + (b - a) * urand();
}

static void apply_h(const double H[9], double x, double y, double *u, double *v)
{
    double w = H[6] * x + H[7] * y + H[8];
    *u = (H[0] * x + H[1] * y + H[2]) / w;
    *v = (H[3] * x + H[4] * y + H[5]) / w;
}

// The degradations: each a camera, a range of tilts and what the photo does.
typedef struct {
    const char *name;
    int w, h;
    double f;                       // focal length, px
    double frac_lo, frac_hi;        // the board's squares' width over the image's
    double tilt_lo, tilt_hi;        // deg
    double q_lo, q_hi;              // JPEG quality
    double light_lo, light_hi;      // the dark side's gain
    double vignette;
    double blur_lo, blur_hi;        // px
    double k1;                      // radial distortion at r = f
    double noise;                   // grey levels
    double bend_px;                 // the paper's waviness, px
    double glare;                   // a highlight's peak over the board, x 255 grey levels
    double margin;                  // the paper's white beyond the outer squares, squares
} degradation_t;

static const degradation_t degs[] = {
    { "JPEG quality 60-90", 1280, 720, 1000, 0.4, 0.75, 0, 35, 60, 90, 1, 1, 0, 0.6, 0.8, 0, 2, 0, 0, 0.5 },
    { "uneven light", 1280, 720, 1000, 0.4, 0.75, 0, 35, 85, 85, 0.25, 0.45, 0.4, 0.6, 0.8, 0, 2, 0, 0, 0.5 },
    { "blur 1.5-2.5 px", 1280, 720, 1000, 0.4, 0.75, 0, 35, 85, 85, 1, 1, 0, 1.5, 2.5, 0, 2, 0, 0, 0.5 },
    { "perspective 45-60 deg", 1280, 720, 1000, 0.4, 0.75, 45, 60, 85, 85, 1, 1, 0, 0.6, 0.8, 0, 2, 0, 0, 0.5 },
    { "barrel distortion", 1280, 720, 700, 0.4, 0.6, 0, 35, 85, 85, 1, 1, 0, 0.6, 0.8, -0.25, 2, 0, 0, 0.5 },
    { "noise 6 DN", 1280, 720, 1000, 0.4, 0.75, 0, 35, 85, 85, 1, 1, 0, 0.6, 0.8, 0, 6, 0, 0, 0.5 },
    { "small squares", 1280, 720, 1000, 0.1, 0.2, 0, 35, 85, 85, 1, 1, 0, 0.6, 0.8, 0, 2, 0, 0, 0.5 },
    { "paper not flat", 1280, 720, 1000, 0.4, 0.75, 0, 35, 85, 85, 1, 1, 0, 0.6, 0.8, 0, 2, 6, 0, 0.5 },
    { "glare", 1280, 720, 1000, 0.4, 0.75, 0, 35, 85, 85, 1, 1, 0, 0.6, 0.8, 0, 2, 0, 0.7, 0.5 },
    { "narrow margin, dim", 1280, 720, 1000, 0.4, 0.75, 0, 35, 70, 70, 0.08, 0.15, 0.6, 0.6, 0.8, 0, 3, 0, 0, 0.15 },
    { "320 x 240 camera", 320, 240, 280, 0.4, 0.75, 0, 45, 60, 90, 0.6, 1, 0.2, 0.5, 0.8, 0, 2, 0, 0, 0.5 },
    { "all of them", 1280, 720, 800, 0.3, 0.6, 0, 60, 60, 90, 0.25, 0.5, 0.4, 1.0, 2.0, -0.2, 4, 4, 0.5, 0.25 },
};
#define NDEG (int)(sizeof degs / sizeof degs[0])
#define VIEWS_PER 8

// A random pose of the board seen whole (its paper inside the image, 4 px
// margin): H_px_board of board mm -> pixel. false: no pose found.
static bool random_pose(const degradation_t *d, double H[9])
{
    const double cx = (d->w - 1) / 2.0, cy = (d->h - 1) / 2.0;
    const double pw = (BW + 3) * SQ, ph = (BH + 3) * SQ;   // the paper
    for (int tries = 0; tries < 200; tries++) {
        double tilt = uni(d->tilt_lo, d->tilt_hi) * DEG, axis = uni(0, 2 * M_PI), turn = uni(-M_PI, M_PI);
        double frac = uni(d->frac_lo, d->frac_hi) * pow(0.99, tries), dist = d->f * (BW + 1) * SQ / (frac * d->w);
        // R = tilt about (cos axis, sin axis, 0), after a turn about z
        double r1[3] = { 0, 0, turn }, r2[3] = { tilt * cos(axis), tilt * sin(axis), 0 }, R1[9], R2[9], R[9];
        mrcal_R_from_r(R1, NULL, r1);
        mrcal_R_from_r(R2, NULL, r2);
        for (int i = 0; i < 3; i++)
            for (int j = 0; j < 3; j++)
                R[3 * i + j] = R2[3 * i] * R1[j] + R2[3 * i + 1] * R1[3 + j] + R2[3 * i + 2] * R1[6 + j];
        // the board's centre on a ray through a random point of the image's middle
        double u0 = cx + uni(-0.2, 0.2) * d->w, v0 = cy + uni(-0.2, 0.2) * d->h;
        double bc[2] = { (BW - 1) * SQ / 2, (BH - 1) * SQ / 2 };
        double t[3] = { (u0 - cx) / d->f * dist, (v0 - cy) / d->f * dist, dist };
        for (int i = 0; i < 3; i++) t[i] -= R[3 * i] * bc[0] + R[3 * i + 1] * bc[1];
        for (int c = 0; c < 3; c++) {
            double col[3] = { c < 2 ? R[c] : t[0], c < 2 ? R[3 + c] : t[1], c < 2 ? R[6 + c] : t[2] };
            H[c] = d->f * col[0] + cx * col[2];
            H[3 + c] = d->f * col[1] + cy * col[2];
            H[6 + c] = col[2];
        }
        bool inside = true;
        for (int k = 0; k < 4; k++) {
            double x = (k & 1 ? pw : 0) - 1.5 * SQ, y = (k & 2 ? ph : 0) - 1.5 * SQ, u, v;
            if (H[6] * x + H[7] * y + H[8] <= 0) inside = false;
            apply_h(H, x, y, &u, &v);
            inside = inside && u > 4 && v > 4 && u < d->w - 5 && v < d->h - 5;
        }
        if (inside) return true;
    }
    return false;
}

// The board printed on paper (black 30, white 234) on a textured grey table,
// then the degradation's photo.
static bool photo(const degradation_t *d, const double H[9], unsigned seed, unsigned char *img, test_photo_t *p)
{
    calib_board_t b = { .kind = CALIB_BOARD_CHESSBOARD, .width_n = BW, .height_n = BH, .spacing_mm = SQ };
    if (!calib_board_render(&b, H, d->w, d->h, 3, img)) return false;
    double det = H[0] * (H[4] * H[8] - H[5] * H[7]) - H[1] * (H[3] * H[8] - H[5] * H[6]) +
                 H[2] * (H[3] * H[7] - H[4] * H[6]);
    double Hi[9] = { (H[4] * H[8] - H[5] * H[7]) / det, (H[2] * H[7] - H[1] * H[8]) / det,
                     (H[1] * H[5] - H[2] * H[4]) / det, (H[5] * H[6] - H[3] * H[8]) / det,
                     (H[0] * H[8] - H[2] * H[6]) / det, (H[2] * H[3] - H[0] * H[5]) / det,
                     (H[3] * H[7] - H[4] * H[6]) / det, (H[1] * H[6] - H[0] * H[7]) / det,
                     (H[0] * H[4] - H[1] * H[3]) / det };
    for (int y = 0; y < d->h; y++)
        for (int x = 0; x < d->w; x++) {
            double bx, by;
            apply_h(Hi, x, y, &bx, &by);
            double m = d->margin * SQ;   // the outer squares span -SQ .. W SQ
            bool paper = bx > -SQ - m && by > -SQ - m && bx < BW * SQ + m && by < BH * SQ + m;
            unsigned char *px = &img[(size_t)y * d->w + x];
            *px = paper ? (unsigned char)lround(30 + *px * 0.8)
                        : (unsigned char)lround(95 + 35 * sin(x * 0.045 + 0.3 * y * 0.01) * cos(y * 0.063));
        }
    *p = (test_photo_t){ .k1 = d->k1, .f_px = d->f, .light_lo = uni(d->light_lo, d->light_hi),
                         .light_dir_deg = uni(0, 360), .vignette = d->vignette,
                         .blur_sigma_px = uni(d->blur_lo, d->blur_hi), .noise_dn = d->noise,
                         .jpeg_quality = (int)lround(uni(d->q_lo, d->q_hi)), .seed = seed,
                         .bend_px = d->bend_px * uni(0.7, 1.0), .glare = d->glare * uni(0.7, 1.0) };
    // the highlight on the board: at a random point of it, a quarter to a half of the board's width across
    double gx = uni(0, (BW - 1) * SQ), gy = uni(0, (BH - 1) * SQ), x0, y0, x1, y1;
    apply_h(H, 0, 0, &x0, &y0);
    apply_h(H, (BW - 1) * SQ, 0, &x1, &y1);
    apply_h(H, gx, gy, &p->glare_x, &p->glare_y);
    p->glare_sigma_px = uni(0.25, 0.5) * hypot(x1 - x0, y1 - y0) / 2;
    return test_photo_degrade(img, d->w, d->h, p);
}

// The corners found against the truth in the detector's order and a half
// turn from it (the caller's ambiguity): RMS and worst of the better, px.
static void corner_errors(const degradation_t *d, const test_photo_t *p, const double H[9], const double *q,
                          double *rms, double *worst)
{
    *rms = *worst = INFINITY;
    for (int turn = 0; turn < 2; turn++) {
        double ss = 0, w = 0;
        for (int k = 0; k < BW * BH; k++) {
            int kk = turn ? BW * BH - 1 - k : k;
            double u, v;
            apply_h(H, (kk % BW) * SQ, (kk / BW) * SQ, &u, &v);
            test_photo_distort(p, d->w, d->h, u, v, &u, &v);
            double e = hypot(q[2 * k] - u, q[2 * k + 1] - v);
            ss += e * e;
            w = fmax(w, e);
        }
        if (sqrt(ss / (BW * BH)) < *rms) {
            *rms = sqrt(ss / (BW * BH));
            *worst = w;
        }
    }
}

// Per degradation (and over all): views, found by each detector alone and by
// the chain, and the corners' error of each (sum of squares of the views'
// RMS, worst corner).
typedef struct {
    int n, found[4];
    double ss[4], worst[4];
} tally_t;

static const char *const dnames[4] = { "opencv-sb", "opencv-classic", "opencv-classic-normalised", "the chain" };
static const unsigned dmask[4] = { CALIB_BOARD_DET_SB, CALIB_BOARD_DET_CLASSIC, CALIB_BOARD_DET_CLASSIC_NORMALISED,
                                   CALIB_BOARD_DET_ALL };

static void tally_add(tally_t *t, int i, double rms, double worst)
{
    t->found[i]++;
    t->ss[i] += rms * rms;
    t->worst[i] = fmax(t->worst[i], worst);
}

static void tally_print(const char *name, const tally_t *t)
{
    fprintf(stderr, "  %-22s %2d views:", name, t->n);
    for (int i = 0; i < 4; i++)
        fprintf(stderr, " %s %d (%.3f / %.3f px)%s", i == 3 ? "chain" : i == 0 ? "sb" : i == 1 ? "classic" : "norm",
                t->found[i], t->found[i] ? sqrt(t->ss[i] / t->found[i]) : NAN, t->worst[i], i < 3 ? "," : "\n");
}

// One view through the chain and through each detector alone; the chain's
// checks (its detector and attempts recorded, the single detector refuted
// where another found it). Returns the chain's detector index, -1 none.
static int one_view(const degradation_t *d, int k, unsigned char *img, tally_t *t, tally_t *all)
{
    calib_board_t b = { .kind = CALIB_BOARD_CHESSBOARD, .width_n = BW, .height_n = BH, .spacing_mm = SQ };
    double q[2 * BW * BH], H[9], rms, w;
    test_photo_t p;
    CHECK_MSG(random_pose(d, H), "%s view %d: no pose with the paper inside the image", d->name, k);
    CHECK(photo(d, H, (unsigned)(1000 + 10 * (d - degs) + k), img, &p));
    int got[4];
    calib_board_how_t how;
    for (int i = 0; i < 4; i++) {
        got[i] = calib_board_detect_how(&b, img, d->w, d->h, q, dmask[i], &how);
        CHECK_MSG(got[i] == 0 || got[i] == BW * BH, "%s view %d: %d corners", d->name, k, got[i]);
        if (got[i] != BW * BH) continue;
        corner_errors(d, &p, H, q, &rms, &w);
        tally_add(t, i, rms, w);
        tally_add(all, i, rms, w);
    }
    t->n++;
    all->n++;
    // how (the chain's, the last call): who found it, each attempt in order
    CHECK(how.attempts[0] != 0);
    if (got[3] != BW * BH) {
        CHECK(how.detector[0] == 0);
        fprintf(stderr, "    %s view %d: not found (%s)\n", d->name, k, how.attempts);
        return -1;
    }
    int di = !strcmp(how.detector, "opencv-sb") ? 0 : !strcmp(how.detector, "opencv-classic") ? 1 : 2;
    CHECK(!strcmp(how.detector, dnames[di]));
    CHECK(got[di] == BW * BH);
    if (di == 0) CHECK(strstr(how.attempts, "opencv-sb: found") == how.attempts);
    else CHECK(strstr(how.attempts, "opencv-sb: ") == how.attempts && !strstr(how.attempts, "opencv-sb: found") &&
               got[0] == 0);
    corner_errors(d, &p, H, q, &rms, &w);
    CHECK_MSG(w < 1.0 || di == 0, "%s view %d (%s): a corner %.3f px off (RMS %.3f)", d->name, k, how.detector, w,
              rms);
    return di;
}

TEST_LONG(calib_boards_photo_detectors)
{
    unsigned char *img = malloc(1280 * 720);
    tally_t all = { 0 };
    int by[3] = { 0 };
    CHECK(img != NULL);
    for (int g = 0; img && g < NDEG; g++) {
        tally_t t = { 0 };
        double t0 = model_realtime_s();
        for (int k = 0; k < VIEWS_PER; k++) {
            int di = one_view(&degs[g], k, img, &t, &all);
            if (di >= 0) by[di]++;
        }
        tally_print(degs[g].name, &t);
        fprintf(stderr, "    (%.1f s)\n", model_realtime_s() - t0);
    }
    tally_print("all", &all);
    fprintf(stderr, "  the chain's views found by opencv-sb %d, opencv-classic %d, opencv-classic-normalised %d\n",
            by[0], by[1], by[2]);
    CHECK(all.n == NDEG * VIEWS_PER);
    CHECK(all.found[3] >= 0.95 * all.n);
    // the corners (RMS over the views, px; worst corner): sub-pixel; the classic detector's, refined by
    // cornerSubPix, within 1 px everywhere; findChessboardCornersSB's own are coarser (up to 2.5 px off under
    // glare and at 45-60 deg)
    double rms[4];
    for (int i = 0; i < 4; i++) rms[i] = all.found[i] ? sqrt(all.ss[i] / all.found[i]) : INFINITY;
    CHECK(rms[3] < 0.25 && rms[0] < 0.25 && rms[1] < 0.15 && rms[2] < 0.15);
    CHECK(all.worst[1] < 1.0 && all.worst[2] < 1.0 && all.worst[3] < 4.0);
    // the single detector misses views the chain finds
    CHECK(all.found[0] < all.found[3]);
    CHECK(by[1] + by[2] == all.found[3] - all.found[0]);
    free(img);
}
